"""Example meshes shipped with the package, as OBJ files.

Each is a built-in surface of `jaxgeo.surfaces` written by `surfaces.save` with the
parameters below (the ones the cutting-pattern tests and notebooks use), so

    jaxgeo surface cone_tent n_around=48 n_radial=12 -o tent.obj

writes the same file as `example_mesh_path("cone_tent")` points to
(`tests/test_surfaces.py` checks that they agree). To regenerate them all:
`python -m jaxgeo.data`.
"""

from __future__ import annotations

from importlib import resources

from .._errors import JaxgeoError

#: name -> generator keyword arguments (the generator is `surfaces.<name>`).
EXAMPLES: dict[str, dict] = {
    # 1152 faces; 16 seams: README's cutting-pattern example
    "cone_tent": {"n_around": 48, "n_radial": 12},
    # 2560 faces, three boundary loops (two peak rings and the outer edge)
    "twin_peak_tent": {"n_side": 8, "n_radial": 10},
    # "four_point_sail": {...},  (added with surfaces.four_point_sail)
}


def example_mesh_path(name: str) -> str:
    """The path of the shipped example mesh `name` (a key of `EXAMPLES`), for
    `jaxgeo.load_mesh` or the command line."""
    if name not in EXAMPLES:
        raise JaxgeoError(
            f"unknown example mesh {name!r}; expected one of {', '.join(EXAMPLES)}"
        )
    return str(resources.files(__name__).joinpath(f"{name}.obj"))


def write_examples() -> list[str]:
    """(Re)write every example file from its generator; returns the paths."""
    from .. import surfaces

    return [
        surfaces.save(name, example_mesh_path(name), **params)
        for name, params in EXAMPLES.items()
    ]
