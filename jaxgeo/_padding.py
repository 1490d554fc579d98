"""Size classes: a mesh's arrays padded to one of a few shapes, so that the
compiled solver of one mesh serves every mesh of its class.

JAX compiles a jitted function once per shape of its arguments; a `Mesh` whose
arrays have their real sizes would compile the solver again for every new mesh
(tens of seconds). The solver is instead handed `padded(mesh)`: the same `Mesh`
pytree with every count rounded up to the grid 2^j, 3·2^(j−1) (1, 2, 3, 4, 6, 8,
12, 16, 24, …: steps of 1.5 and 1.33, √2 on average), so a mesh shares its compiled
code (in memory and in the persistent compilation cache, both keyed by shapes)
with every mesh of the same `SizeClass`:

- V vertices → `size_class(V + 1)`, at least 64 (always one padded vertex);
- F faces → `size_class(F + 1)`, at least 64;
- B boundary edges → 0 for a closed mesh, else `size_class(B)`, at least 16;
- E edges → (3 F_c + B_c) / 2, the count a manifold mesh of F_c faces and B_c
  boundary edges has (2E = 3F + B), so `normals.fit_boundary_normals`' static
  boundary count 2E − 3F is the class's B_c (≥ B);
- K, the widest vertex fan → `size_class(K)`, at least 6.

The padding is inert. Padded vertices sit at the centre of the mesh's bounding box
(inside it: the trace's frame is unchanged) in no face's fan (`fan_size` 0,
`vertex_faces` −1, so off the boundary: `boundary_next` −1), landmark distance inf
and predecessor −1; padded edges' predecessor −1), so no start or path reaches them.
Padded faces are the point-like triangle (V, V, V) of the first padded vertex, with
`face_component` −1 (`locate` skips them), `corner_angles` 0 and `face_edges` the
first padded edge; padded edges are (V, V) with `edge_faces` (−1, −1) (the laser's
`candidates="all"` skips them; real edges always have a face); padded vertices'
angle sums are 0 and the per-component facts (`component_*`) False past the real
labels, which no face carries. Real elements keep
their indices, so paths on the padded mesh name the same faces, edges and vertices
as on the real one. `jnp` padding of the vertices is differentiable: gradients flow
back to the real rows (the padded rows' value is a `stop_gradient`).

The padded topology of a concrete mesh is built once, in numpy, and cached while its
arrays live (`Mesh.with_vertices` shares it); a traced mesh (inside the user's
`jax.jit`) is padded with `jnp` as part of the trace. The fields that follow the
vertices (`GEOMETRY`) are padded and cached with them.
"""

from __future__ import annotations

import dataclasses
import weakref
from typing import TYPE_CHECKING, Any, NamedTuple

import jax
import jax.core
import jax.numpy as jnp
import numpy as np

if TYPE_CHECKING:
    from .mesh import Mesh

#: Smallest class of each count (tiny meshes share one class).
MIN_VERTICES = 64
MIN_FACES = 64
MIN_BOUNDARY = 16
MIN_FAN = 6


def size_class(n: int, least: int = 1) -> int:
    """The smallest 2^j or 3·2^(j−1) that is at least `max(n, least)`."""
    n = max(int(n), int(least), 1)
    power = 1 << (n - 1).bit_length()  # smallest power of two ≥ n
    three = 3 * power // 4
    return three if power >= 4 and three >= n else power


class SizeClass(NamedTuple):
    """The padded counts of a mesh: vertices, faces, edges, boundary edges, fan
    width."""

    vertices: int
    faces: int
    edges: int
    boundary: int
    fan: int


def mesh_class(n_vertices: int, n_faces: int, n_edges: int, fan: int) -> SizeClass:
    """The `SizeClass` of a mesh with these counts (`fan`: its widest fan)."""
    boundary = 2 * n_edges - 3 * n_faces
    v = size_class(n_vertices + 1, MIN_VERTICES)
    f = size_class(n_faces + 1, MIN_FACES)
    b = 0 if boundary <= 0 else size_class(boundary, MIN_BOUNDARY)
    return SizeClass(v, f, (3 * f + b) // 2, b, size_class(fan, MIN_FAN))


def class_of(mesh: Mesh) -> SizeClass:
    return mesh_class(
        mesh.vertices.shape[0],
        mesh.faces.shape[0],
        mesh.edges.shape[0],
        mesh.vertex_faces.shape[1],
    )


#: How each field of `Mesh` is padded: per axis the count it runs over ("V", "F",
#: "E", "K", "K1" = K + 1, or None: kept), and the fill value ("V": the first
#: padded vertex, "E": the first padded edge). `vertices` is special (see
#: `_pad_vertices`). A new field of `Mesh` needs a rule here (`padded` refuses a
#: mesh with a field it does not know).
RULES: dict[str, tuple[tuple[str | None, ...], Any]] = {
    "faces": (("F", None), "V"),
    "edges": (("E", None), "V"),
    "edge_faces": (("E", None), -1),
    "face_edges": (("F", None), "E"),
    "vertex_faces": (("V", "K"), -1),
    "face_component": (("F",), -1),
    "mean_edge_length": ((), 0),
    "fan_faces": (("V", "K"), -1),
    "fan_spokes": (("V", "K1"), -1),
    "fan_size": (("V",), 0),
    "fan_closed": (("V",), False),
    "corner_fan_pos": (("F", None), 0),
    "landmark_pred_vertex": ((None, "V"), -1),
    "landmark_pred_edge": ((None, "E"), -1),
    "landmark_dist": ((None, "V"), np.inf),
    "edge_cut": (("E",), 0),
    "corner_angles": (("F", None), 0.0),
    "vertex_angle_sums": (("V",), 0.0),
    "component_cone_free": (("F",), False),
    "component_disc": (("F",), False),
    "component_annulus": (("F",), False),
    "component_systole": (("F",), 0.0),
}


def _is_traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _pad_field(name: str, x, real: dict[str, int], size: dict[str, int]):
    axes, fill = RULES[name]
    if isinstance(fill, str):
        fill = real[fill]
    widths = [(0, 0 if a is None else size[a] - n) for a, n in zip(axes, x.shape)]
    if not any(w for _, w in widths):
        return x
    if _is_traced(x):
        return jnp.pad(x, widths, constant_values=fill)
    return jnp.asarray(np.pad(np.asarray(x), widths, constant_values=fill))


def _pad_vertices(v, n: int):
    """`v` with `n` rows appended at the centre of its bounding box (a constant:
    no gradient flows through the padded rows)."""
    if n == 0:
        return v
    if _is_traced(v):
        w = jax.lax.stop_gradient(v)
        centre = (jnp.min(w, axis=0) + jnp.max(w, axis=0)) / 2
        return jnp.concatenate([v, jnp.broadcast_to(centre, (n, 3)).astype(v.dtype)])
    a = np.asarray(v)
    centre = (a.min(axis=0) + a.max(axis=0)) / 2
    return jnp.asarray(np.concatenate([a, np.broadcast_to(centre, (n, 3))]))


#: The fields that follow the vertex positions (`Mesh.with_vertices` replaces
#: them), padded and cached with the vertices rather than with the topology.
GEOMETRY = (
    "vertices",
    "corner_angles",
    "vertex_angle_sums",
    "component_cone_free",
    "component_systole",
)


def _topology_names(mesh: Mesh) -> list[str]:
    """The fields of `mesh` that do not follow the vertices."""
    return [f.name for f in dataclasses.fields(mesh) if f.name not in GEOMETRY]


def _pad_fields(mesh: Mesh, c: SizeClass, names) -> dict[str, Any]:
    """The fields `names` of `mesh` padded to class `c` (by `RULES`)."""
    real = {"V": mesh.vertices.shape[0], "E": mesh.edges.shape[0]}
    size = {"V": c.vertices, "F": c.faces, "E": c.edges, "K": c.fan, "K1": c.fan + 1}
    return {k: _pad_field(k, getattr(mesh, k), real, size) for k in names}


#: Padded topology per concrete mesh, by the identity of its `faces` array:
#: `(weakrefs to the real topology arrays, padded fields, (weakref to the real
#: vertices, padded `GEOMETRY` fields) or None)`; dropped when `faces` is
#: collected.
_CACHE: dict[int, tuple[dict[str, weakref.ref], dict[str, Any], Any]] = {}


def _cached_topology(mesh: Mesh, c: SizeClass) -> dict[str, Any]:
    names = _topology_names(mesh)
    key = id(mesh.faces)
    hit = _CACHE.get(key)
    if hit is not None and all(hit[0][k]() is getattr(mesh, k) for k in names):
        return hit[1]
    fields = _pad_fields(mesh, c, names)
    if any(_is_traced(x) for x in fields.values()):
        return fields  # padded inside an outer jit's trace: must not outlive it

    def drop(ref, key=key):
        entry = _CACHE.get(key)
        if entry is not None and entry[0]["faces"] is ref:
            del _CACHE[key]

    refs = {k: weakref.ref(getattr(mesh, k)) for k in names}
    refs["faces"] = weakref.ref(mesh.faces, drop)
    _CACHE[key] = (refs, fields, None)
    return fields


#: The padded mesh of each concrete mesh, by the mesh's identity (a `Mesh` is
#: immutable): `(weakref to the mesh, padded mesh)`, dropped with the mesh.
#: `shortest_path` pads on every call: building it again from the field
#: caches below cost 0.1–0.25 ms.
_PADDED: dict[int, tuple[weakref.ref, Mesh]] = {}


def padded(mesh: Mesh) -> Mesh:
    """`mesh` with its arrays padded to its `SizeClass` (see the module
    docstring): what the jitted solvers are handed. Differentiable in
    `mesh.vertices`; works on concrete and traced meshes."""
    key = id(mesh)
    hit = _PADDED.get(key)
    if hit is not None and hit[0]() is mesh:
        return hit[1]
    out = _padded(mesh)
    if not any(_is_traced(x) for x in jax.tree.leaves((mesh, out))):

        def drop(ref, key=key):
            entry = _PADDED.get(key)
            if entry is not None and entry[0] is ref:
                del _PADDED[key]

        _PADDED[key] = (weakref.ref(mesh, drop), out)
    return out


def _padded(mesh: Mesh) -> Mesh:
    unknown = {f.name for f in dataclasses.fields(mesh)} - set(RULES) - {"vertices"}
    if unknown:
        raise AssertionError(f"no padding rule for Mesh field(s) {sorted(unknown)}")
    c = class_of(mesh)
    topology = _topology_names(mesh)
    if any(_is_traced(getattr(mesh, k)) for k in topology):
        fields = _pad_fields(mesh, c, topology)
    else:
        fields = _cached_topology(mesh, c)
    v = mesh.vertices
    entry = None if _is_traced(v) else _CACHE.get(id(mesh.faces))
    if entry is not None and entry[2] is not None and entry[2][0]() is v:
        padded_geometry = entry[2][1]
    else:
        padded_geometry = _pad_fields(mesh, c, GEOMETRY[1:])
        padded_geometry["vertices"] = _pad_vertices(v, c.vertices - v.shape[0])
        # under an outer jit a concrete mesh is padded inside the trace: the
        # result is then a tracer of that trace and must not outlive it
        if entry is not None and not any(
            _is_traced(x) for x in padded_geometry.values()
        ):
            _CACHE[id(mesh.faces)] = (
                entry[0],
                entry[1],
                (weakref.ref(v), padded_geometry),
            )
    fields.update(padded_geometry)
    names = [f.name for f in dataclasses.fields(mesh)]
    flat, treedef = jax.tree.flatten(mesh)
    if len(flat) != len(names) or any(
        x is not getattr(mesh, k) for x, k in zip(flat, names)
    ):
        raise AssertionError("Mesh leaves are not its fields in order")
    return jax.tree.unflatten(treedef, [fields[k] for k in names])
