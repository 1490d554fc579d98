"""A warning, once per process, when float64 input meets JAX's float32 default.

JAX runs in float32 unless `jax_enable_x64` is on, and then converts float64
arrays to float32 without a word. jaxgeo works in float32, but a user who passes
float64 data (numpy's default, and `jaxgeo.surfaces`') almost always meant float64.
"""

from __future__ import annotations

import os
import sys
import warnings
from typing import Any

import jax
import numpy as np


class PrecisionWarning(UserWarning):
    """float64 input while JAX runs in float32 (`jax_enable_x64` off)."""


#: The warning's text: what happened, what it costs, how to fix it.
MESSAGE = (
    "jaxgeo got float64 input but JAX runs in float32 (jax_enable_x64 is off), so "
    "it computes in float32: lengths and points carry ~1e-7 relative error "
    "(float32's rounding), gradients are noisier and method='smooth' may fail to "
    "converge. For float64 run `jax.config.update('jax_enable_x64', True)` (or set "
    "JAX_ENABLE_X64=1) before creating any JAX array; to keep float32 and silence "
    "this, pass float32 arrays."
)

_warned = False


def _is_float64(x: Any) -> bool:
    # JAX arrays and tracers are float32 already when x64 is off: only host data
    # (numpy, Python floats) can be float64.
    dtype = getattr(x, "dtype", None)
    if dtype is None:
        try:
            dtype = np.asarray(x).dtype
        except Exception:  # not array-like: the caller's checks will say so
            return False
    return dtype == np.float64


def _stacklevel() -> int:
    """The `stacklevel` of the first frame outside jaxgeo and equinox (which wraps
    `Mesh.__init__`), so the warning names the user's line."""
    import equinox

    here = os.path.dirname(os.path.abspath(__file__))
    internal = (here, os.path.dirname(os.path.abspath(equinox.__file__)))
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(
        internal
    ):
        frame, level = frame.f_back, level + 1
    return level


def warn_if_x64_disabled(*arrays: Any) -> bool:
    """Warn (once per process, `PrecisionWarning`) if any of `arrays` is float64
    while `jax_enable_x64` is off. Python floats and lists count as float64, as
    numpy reads them. Returns whether the condition holds (warned now or before)."""
    global _warned
    # (JAX's flags are attributes that jax.config sets at run time)
    if jax.config.jax_enable_x64 or not any(_is_float64(a) for a in arrays):  # pyright: ignore[reportAttributeAccessIssue]
        return False
    if not _warned:
        _warned = True
        warnings.warn(MESSAGE, PrecisionWarning, stacklevel=_stacklevel())
    return True


def float32_note(dtype: Any) -> str:
    """A clause to append to an error message when the computation ran in float32
    (empty otherwise), e.g. for a solver that did not converge."""
    if np.dtype(dtype) != np.float32:
        return ""
    return (
        " (the mesh is float32; float32 rounding (~1e-7 relative) may be the cause: "
        "enable float64 with jax.config.update('jax_enable_x64', True))"
    )
