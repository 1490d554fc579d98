"""Where jaxgeo's warnings point: the first frame of the caller's code."""

from __future__ import annotations

import os
import sys

import equinox as eqx
import jaxtyping


def caller_stacklevel() -> int:
    """The `stacklevel` that points a warning at the first frame outside jaxgeo and
    equinox (whose module machinery wraps `Mesh.__init__`), and outside the type
    checks that jaxtyping's import hook wraps round jaxgeo's functions in tests
    (jaxtyping's frames and beartype's generated `<@beartype(...)>` ones)."""
    here = os.path.dirname(os.path.abspath(__file__))
    internal = tuple(
        os.path.dirname(os.path.abspath(f))
        for f in (__file__, eqx.__file__, jaxtyping.__file__)
    )
    frame, level = sys._getframe(1), 1
    # the frame that calls warnings.warn: our caller, past the checks round us
    while frame is not None and not frame.f_code.co_filename.startswith(here):
        frame = frame.f_back
    while frame is not None and (
        os.path.abspath(frame.f_code.co_filename).startswith(internal)
        or frame.f_code.co_filename.startswith("<@beartype")
    ):
        frame, level = frame.f_back, level + 1
    return level
