"""Every annotation in the package evaluates (no JAX work: fast).

`Float[Array, 3]` (an int where jaxtyping wants a string of dimensions) is accepted
when a module is imported, since annotations are strings there (`from __future__
import annotations`), and raises only when something reads them: jaxtyping's
runtime checking, `typing.get_type_hints`, documentation tools. This test reads
them all. Names imported under `TYPE_CHECKING` (to avoid import cycles) are
resolved from the package's public names.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import typing

import jaxgeo


def _defined_in(module) -> list:
    out = []
    for obj in vars(module).values():
        if getattr(obj, "__module__", None) != module.__name__:
            continue
        if inspect.isfunction(obj):
            out.append(obj)
        elif inspect.isclass(obj):
            out.append(obj)
            out += [f for f in vars(obj).values() if inspect.isfunction(f)]
    return out


def test_every_annotation_evaluates():
    public = {k: v for k, v in vars(jaxgeo).items() if not k.startswith("_")}
    bad, checked = [], 0
    for info in pkgutil.walk_packages(jaxgeo.__path__, "jaxgeo."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for obj in _defined_in(module):
            checked += 1
            try:
                typing.get_type_hints(obj, localns=public)
            except Exception as e:  # noqa: BLE001 (any failure is the finding)
                bad.append(f"{info.name}.{obj.__qualname__}: {e!r}")
    assert checked > 200  # the walk found the package's functions
    assert not bad, "\n".join(bad)


def test_calls_are_checked_against_the_annotations():
    """pyproject.toml's pytest addopts install jaxtyping's import hook over jaxgeo
    (beartype as the checker): a call that breaks an annotation fails in the
    tests, wherever it comes from."""
    import jaxtyping
    import numpy as np
    import pytest

    from jaxgeo.normals import edge_normal

    with pytest.raises(jaxtyping.TypeCheckError, match="parameter 'n2'"):
        edge_normal(np.zeros(3), np.zeros(2), 0.5)  # n2: Float[..., "3"]
