"""Export of paths: JSON, CSV and OBJ polylines."""

from __future__ import annotations

import io
import json

import numpy as np

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
        lines = [f"# jaxgeo path, length {d['length']:.17g}, status {d['status']}"]
        lines += [f"v {p[0]:.17g} {p[1]:.17g} {p[2]:.17g}" for p in d["points"]]
        lines.append("l " + " ".join(str(i + 1) for i in range(d["count"])))
        return "\n".join(lines) + "\n"
    raise ValueError(f"unknown format {fmt!r}; expected one of {FORMATS}")
