"""Paths as text: JSON, CSV and OBJ polylines (`format_path`), and the one OBJ
polyline writer (`obj_polylines`) that `jaxgeo.export.write_seams_obj` uses
too. (Cutting patterns, DXF and SVG, are `jaxgeo.export`'s.)"""

from __future__ import annotations

import io
import json
from collections.abc import Sequence

import numpy as np
from jaxtyping import Float

from .path import Path, Status

FORMATS = ("json", "csv", "obj")


def path_to_dict(path: Path) -> dict:
    """A JSON-ready description of a path (the live part of its buffers), with
    its endpoints (`start`, `end`: face and barycentric coordinates) and the
    method's `stats` when it has them (a NaN, as a failed row may hold, is
    written as null)."""
    n = int(path.count)
    extra: dict = {}
    for name, sp in (("start", path.start), ("end", path.end)):
        if sp is not None:
            bary = np.asarray(sp.bary, float).tolist()
            extra[name] = {"face": int(np.asarray(sp.face)), "bary": _finite(bary)}
    if path.stats:
        extra["stats"] = {
            k: _finite(np.asarray(v).item()) for k, v in path.stats.items()
        }
    return {
        "status": Status(int(path.status)).name.lower(),
        "length": float(path.length),
        "count": n,
        "branch_points": int(np.asarray(path.branch)[:n].sum()),
        "points": np.asarray(path.points)[:n].tolist(),
        "kinds": np.asarray(path.kinds)[:n].tolist(),
        "elements": np.asarray(path.elements)[:n].tolist(),
        "params": np.asarray(path.params)[:n].tolist(),
        **extra,
    }


def _finite(x):
    """`x` (a number or a list of them) with NaN and ±inf as None (JSON's
    null: `json.dumps` would write NaN, which JSON does not have)."""
    if isinstance(x, list):
        return [_finite(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def format_path(path: Path, fmt: str) -> str:
    """The path as text: `json` (everything), `csv` (x,y,z,kind,element,param) or
    `obj` (vertices and one polyline `l` element)."""
    d = path_to_dict(path)
    if fmt == "json":
        return json.dumps(d, indent=2)
    if fmt == "csv":
        buf = io.StringIO()
        buf.write("x,y,z,kind,element,param\n")
        for p, k, e, u in zip(d["points"], d["kinds"], d["elements"], d["params"]):
            buf.write(f"{p[0]:.17g},{p[1]:.17g},{p[2]:.17g},{k},{e},{u:.17g}\n")
        return buf.getvalue()
    if fmt == "obj":
        comment = f"jaxgeo path, length {d['length']:.17g}, status {d['status']}"
        return obj_polylines([np.asarray(d["points"])], comment=comment)
    raise ValueError(f"unknown format {fmt!r}; expected one of {FORMATS}")


def obj_polylines(
    polylines: Sequence[Float[np.ndarray, "_ 3"]],
    names: Sequence[str] | None = None,
    comment: str | None = None,
) -> str:
    """3-D polylines as OBJ text: per polyline an optional `o NAME`, its `v`
    records and one `l` element (17 significant digits: coordinates round-trip)."""
    lines = [] if comment is None else [f"# {comment}"]
    base = 1
    for k, pl in enumerate(polylines):
        if names is not None:
            lines.append(f"o {names[k]}")
        lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in np.asarray(pl)]
        lines.append("l " + " ".join(str(base + i) for i in range(len(pl))))
        base += len(pl)
    return "\n".join(lines) + "\n"
