"""The `jaxgeo` command line.

Exit status: 0 on success; 1 when `jaxgeo paths` could not complete some paths (or
`jaxgeo pattern` does not fit the roll); 2 for a usage error or bad input (a
missing option, an unreadable file, a point far from the mesh, a path that cannot
be completed by `jaxgeo path`).

One module per subcommand, each with its `add_*_parser` and the function it runs:
`path`, `paths`, `surface`, `validate`, `pattern`; `common` holds what `path` and
`paths` share (the usage error, formats, mesh loading, solver options). This module
assembles the parser and runs `main`, the console script `jaxgeo`. The subcommand
modules import the library inside their functions, so that `jaxgeo --help` does not
load what only a command needs (validation, cutting, matplotlib, ezdxf).
"""

from __future__ import annotations

import argparse
import sys

from .common import (
    EXAMPLE as EXAMPLE,
    FORMATS as FORMATS,
    UsageError as UsageError,
)
from .path import (
    EXAMPLE_FROM as EXAMPLE_FROM,
    EXAMPLE_TO as EXAMPLE_TO,
    add_path_parser,
)
from .paths import add_paths_parser, read_pairs as read_pairs
from .surface import add_surface_parser
from .validate import VALIDATE_RESOLUTION as VALIDATE_RESOLUTION, add_validate_parser


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="jaxgeo",
        description="Differentiable geodesics on triangle meshes. Coordinates and "
        "lengths are in the mesh's units.",
        epilog="Exit status: 0 success; 1 some paths of `paths` failed (or a "
        "pattern does not fit); 2 usage error or bad input.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    add_path_parser(sub)
    add_paths_parser(sub)
    add_surface_parser(sub)
    add_validate_parser(sub)

    # imported here, as before the split: `python -m jaxgeo.cli.pattern` (its
    # stand-alone main) then runs a module the package has not imported yet
    from .pattern import add_pattern_parser

    add_pattern_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    import jax

    from .._cache import enable_compilation_cache, limit_blas_threads
    from .._errors import JaxgeoError

    # one BLAS thread unless OPENBLAS_NUM_THREADS / OMP_NUM_THREADS say
    # otherwise: the flattening's LAPACK threads spin on a busy CPU
    limit_blas_threads()
    jax.config.update("jax_enable_x64", True)
    # Compiled solvers are cached on disk: the second run of a command skips the
    # JIT compilation that dominates a short run.
    enable_compilation_cache()
    try:
        args = build_parser().parse_args(argv)
        try:
            return args.func(args)
        except UsageError as e:
            args.parser.error(str(e))  # prints the usage; exits with status 2
        except JaxgeoError as e:
            print(f"jaxgeo: error: {e}", file=sys.stderr)
            return 2
    except SystemExit as e:  # argparse: --help (0) and usage errors (2)
        return e.code if isinstance(e.code, int) else 2
    return 0
