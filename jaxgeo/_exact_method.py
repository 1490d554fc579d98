"""`method="exact"`: the laser ray's corridor refined to the exact polyhedral
geodesic (`jaxgeo.refine`), wrapped so that it runs inside `jax.jit`/`jax.vmap`
and is differentiable.

The refinement is combinatorial numpy code. It runs through `jax.pure_callback`
on the concrete values (under `vmap` one query at a time) and returns fixed-size
arrays: the polyline and the frozen combinatorics (`PathStructure`), padded to the
path capacity. The length is then recomputed in JAX from that structure
(`refine._structure_length`), which is what carries the gradient: by the envelope
theorem the derivative of the minimal length is the partial derivative at the
optimal crossings, so no implicit correction is needed (see `jaxgeo.refine`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._corridor import EndPoint, clean_corridor, topology
from ._errors import JaxgeoError
from .locate import SurfacePoint
from .mesh import Mesh
from .path import EDGE, FACE, VERTEX, Path, Status, pad_tail
from .refine import PathStructure, _exact_geodesic_numpy, _structure_length
from .smooth import smooth_geodesic, smooth_shortest_path

_STEP_FIELDS = (
    "step_l",
    "step_r",
    "step_w",
    "step_apex",
    "step_first",
    "step_keep_left",
)
_SEG_FIELDS = ("seg_first", "seg_last", "seg_has_steps", "seg_mask")
_SEG_VERTS = ("a_vid", "a_src", "b_vid", "b_src")


def laser_corridor(
    topo, edge_faces, kinds, elements, count, start: EndPoint, end: EndPoint
) -> list[int]:
    """The faces a traced path crosses, in order, consecutive faces sharing an edge
    (through a vertex point, the shorter way round the vertex's fan). An endpoint
    at a vertex or on an edge lies in all the faces round it: the trace may leave
    it through any of them, not only through the face it was located in."""
    n = int(count)
    sets = []
    for i, (k, e) in enumerate(zip(kinds[:n], elements[:n])):
        if k == FACE and i in (0, n - 1):
            sets.append((start if i == 0 else end).faces(topo))
        elif k == FACE:
            sets.append({int(e)})
        elif k == EDGE:
            sets.append(set(edge_faces[int(e)].tolist()) - {-1})
        else:
            sets.append(set(topo.vertex_faces[int(e)].tolist()) - {-1})
    corridor: list[int] = []
    for i in range(n - 1):
        common = sets[i] & sets[i + 1]
        if not common:
            return []
        face = min(common)
        if corridor and face != corridor[-1] and kinds[i] == VERTEX:
            v = int(elements[i])
            ways = [topo.fan(v, corridor[-1], face, ccw) for ccw in (True, False)]
            ways = [w for w in ways if w is not None]
            if not ways:
                return []
            corridor.extend(min(ways, key=len)[1:])
        elif not corridor or face != corridor[-1]:
            corridor.append(face)
    return corridor


def _pad_structure(st: PathStructure, faces0: np.ndarray, cap: int) -> dict:
    out = {}
    n_steps = np.asarray(st.step_l).shape[0]
    if n_steps > cap or np.asarray(st.seg_mask).shape[0] > cap:
        raise JaxgeoError("exact path longer than max_points")
    pad_step = {
        "step_l": faces0[0],
        "step_r": faces0[1],
        "step_w": faces0[2],
        "step_apex": faces0[2],
        "step_first": True,
        "step_keep_left": False,
    }
    for name in _STEP_FIELDS:
        a = np.asarray(getattr(st, name))
        out[name] = np.concatenate(
            [a, np.full(cap - a.shape[0], pad_step[name], a.dtype)]
        )
    for name in _SEG_FIELDS + _SEG_VERTS:
        a = np.asarray(getattr(st, name))
        fill = 7 if name.endswith("_src") else 0
        padding = np.full((cap - a.shape[0],) + a.shape[1:], fill, a.dtype)
        out[name] = np.concatenate([a, padding])
    return out


def _result_shapes(cap: int, dtype):
    i32, b = jnp.int32, jnp.bool_
    shapes = {
        "points": ((cap, 3), dtype),
        "kinds": ((cap,), i32),
        "elements": ((cap,), i32),
        "params": ((cap,), dtype),
        "count": ((), i32),
        "status": ((), i32),
    }
    for name in _STEP_FIELDS[:4]:
        shapes[name] = ((cap,), i32)
    shapes["step_first"] = ((cap,), b)
    shapes["step_keep_left"] = ((cap,), b)
    shapes["seg_first"] = ((cap,), i32)
    shapes["seg_last"] = ((cap,), i32)
    shapes["seg_has_steps"] = ((cap,), b)
    shapes["seg_mask"] = ((cap,), b)
    for name in _SEG_VERTS:
        shapes[name] = ((cap, 3), i32)
    return {k: jax.ShapeDtypeStruct(s, d) for k, (s, d) in shapes.items()}


def _refine_numpy(
    treedef, cap, dtype, smooth, leaves, start, end, laser, initial, normals
):
    """The pure callback: numpy in, fixed-size numpy out. With `smooth`, the exact
    path's strip is then repaired for the Phong surface of the vertex `normals`
    (`smooth_shortest_path`), and the polyline returned is that strip's."""
    shapes = _result_shapes(cap, dtype)
    out = {k: np.zeros(s.shape, s.dtype) for k, s in shapes.items()}
    out["status"] = np.int32(initial)
    if initial >= 0:
        return out
    mesh = jax.tree.unflatten(treedef, [np.asarray(x) for x in leaves])
    topo = topology(mesh)
    s_face, s_bary = int(start[0]), np.asarray(start[1], np.float64)
    e_face, e_bary = int(end[0]), np.asarray(end[1], np.float64)
    kinds, elements, count, status = (np.asarray(x) for x in laser)
    corridors = []
    if int(status) == Status.SUCCESS:
        s_pt, e_pt = EndPoint(topo, s_face, s_bary), EndPoint(topo, e_face, e_bary)
        c = laser_corridor(
            topo, np.asarray(mesh.edge_faces), kinds, elements, count, s_pt, e_pt
        )
        if c:
            corridors.append(clean_corridor(c, s_pt, e_pt, topo))
    try:
        path = _exact_geodesic_numpy(mesh, s_face, s_bary, e_face, e_bary, corridors)
        n = int(np.asarray(path.points).shape[0])
        if n > cap:
            out["status"] = np.int32(Status.MAX_STEPS)
            return out
        out.update(_pad_structure(path.structure, np.asarray(mesh.faces[0]), cap))
        ok = bool(np.asarray(path.converged))
        if smooth and ok:
            path, n, ok = _smooth_strip(mesh, start, end, path, cap, normals)
    except Exception:  # noqa: BLE001 - a callback must return, never raise
        out["status"] = np.int32(Status.REFINE_FAILED)
        return out
    for name in ("points", "kinds", "elements", "params"):
        a = np.asarray(getattr(path, name))[:n]
        out[name][:n] = a
    out["count"] = np.int32(n)
    out["status"] = np.int32(Status.SUCCESS if ok else Status.REFINE_FAILED)
    return {k: np.asarray(v, shapes[k].dtype) for k, v in out.items()}


def _smooth_strip(mesh, start, end, path, cap, normals):
    s = SurfacePoint(np.asarray(start[0]), np.asarray(start[1], np.float64))
    e = SurfacePoint(np.asarray(end[0]), np.asarray(end[1], np.float64))
    inner = slice(1, int(np.asarray(path.points).shape[0]) - 1)
    sp = smooth_shortest_path(
        mesh,
        s,
        e,
        np.asarray(path.elements)[inner],
        np.asarray(path.params)[inner],
        np.asarray(path.kinds)[inner],
        capacity=cap,
        normals=np.asarray(normals),
    )
    return sp, int(sp.count), bool(np.asarray(sp.valid_strip))


def exact_path(
    mesh: Mesh,
    start: SurfacePoint,
    end: SurfacePoint,
    laser: Path,
    initial_status,
    smooth_normals=None,
) -> Path:
    """The exact polyhedral geodesic, starting from the laser path's corridor and a
    Dijkstra corridor; jit/vmap-compatible, length differentiable in the vertices
    and the endpoints' barycentric coordinates."""
    cap = laser.points.shape[0]
    dtype = mesh.vertices.dtype
    leaves, treedef = jax.tree.flatten(jax.lax.stop_gradient(mesh))
    # the repair of the smooth strip uses the same normals as the final solve
    normals = jnp.zeros((0, 3), dtype) if smooth_normals is None else smooth_normals
    res = jax.pure_callback(
        lambda *a: _refine_numpy(treedef, cap, dtype, smooth_normals is not None, *a),
        _result_shapes(cap, dtype),
        leaves,
        jax.lax.stop_gradient((start.face, start.bary)),
        jax.lax.stop_gradient((end.face, end.bary)),
        (laser.kinds, laser.elements, laser.count, laser.status),
        initial_status,
        jax.lax.stop_gradient(normals),
        vmap_method="sequential",
    )
    ok = res["status"] == Status.SUCCESS
    count = jnp.maximum(res["count"], 1)
    if smooth_normals is not None:
        return _smooth_result(mesh, start, end, laser, res, ok, count, smooth_normals)
    st = PathStructure(**{k: res[k] for k in _STEP_FIELDS + _SEG_FIELDS + _SEG_VERTS})
    sb = start.bary / jnp.sum(start.bary)
    eb = end.bary / jnp.sum(end.bary)
    coef = jnp.concatenate([sb, eb, jnp.array([1.0, 0.0], dtype=dtype)])
    length = _structure_length(mesh.vertices, st, coef)
    points = jnp.where(ok, pad_tail(res["points"], count), laser.points)
    return Path(
        points=points,
        kinds=jnp.where(ok, res["kinds"], laser.kinds),
        elements=jnp.where(ok, res["elements"], laser.elements),
        params=jnp.where(ok, res["params"], laser.params),
        branch=jnp.zeros_like(laser.branch),
        count=jnp.where(ok, count, laser.count),
        length=jnp.where(ok, length, laser.length),
        status=res["status"],
    )


def _smooth_result(mesh, start, end, laser, res, ok, count, normals) -> Path:
    """The geodesic of the Phong surface on the repaired strip, solved again in
    JAX so that it is differentiable (envelope theorem, see `jaxgeo.smooth`)."""
    inner = jnp.maximum(count - 2, 0)
    sp = smooth_geodesic(
        mesh,
        start,
        end,
        res["elements"][1:-1],
        res["params"][1:-1],
        res["kinds"][1:-1],
        count=inner,
        normals=normals,
    )
    cap = laser.points.shape[0]
    pad = cap - sp.points.shape[0]

    def fit(a):
        return jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]) if pad else a

    good = ok & sp.converged
    status = jnp.where(ok & ~sp.converged, Status.REFINE_FAILED, res["status"])
    return Path(
        points=jnp.where(good, fit(sp.points), laser.points),
        kinds=jnp.where(good, fit(sp.kinds), laser.kinds),
        elements=jnp.where(good, fit(sp.elements), laser.elements),
        params=jnp.where(good, fit(sp.params), laser.params),
        branch=jnp.zeros_like(laser.branch),
        count=jnp.where(good, sp.count, laser.count),
        length=jnp.where(good, sp.length, laser.length),
        status=status.astype(jnp.int32),
    )
