"""The strip repair's fan walk (`jaxgeo._smooth_repair.fan_arc`, read from the
mesh's fan tables) against a walk across `edge_faces`, face by face."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgeo as jg
from jaxgeo import _smooth_repair, surfaces


def walk_across_edges(mesh, v, f_in, f_out):
    """`fan_arc`'s result by walking from face to face across `edge_faces`: way 0
    leaves each face by its edge (v, corner after v's successor), way 1 by the
    other edge at v."""
    faces, face_edges = np.asarray(mesh.faces), np.asarray(mesh.face_edges)
    edge_faces = np.asarray(mesh.edge_faces)
    k = max(mesh.vertex_faces.shape[1], 1)
    edges, before = np.zeros((2, k), int), np.zeros((2, k), int)
    n, ok = np.zeros(2, int), np.full(2, f_in == f_out)
    for way in (0, 1):
        face = f_in
        for t in range(k if f_in != f_out else 0):
            i = int(np.argmax(faces[face] == v))
            e = face_edges[face, (i + 1 + way) % 3]
            edges[way, t], before[way, t] = e, face
            pair = edge_faces[e]
            face = pair[1] if pair[0] == face else pair[0]
            if face == f_out:
                n[way], ok[way] = t + 1, True
            if face == f_out or face < 0:
                break
    return edges, before, n, ok


@pytest.mark.parametrize(
    "mesh",
    [
        jg.Mesh(*surfaces.cone_tent(8, 3, outer_radius=1.0, inner_radius=0.2)),
        jg.Mesh(*surfaces.icosphere(1)),
    ],
    ids=["open", "closed"],
)
def test_fan_arc_is_the_walk_across_edges(mesh):
    """Every (vertex, face in its fan, face in its fan), each way round, and a
    face outside the fan (never reached: a closed fan goes round again, an open
    one stops at the boundary); on the padded mesh too."""
    vf = np.asarray(mesh.vertex_faces)
    rows = []
    for v in range(mesh.n_vertices):
        fan = vf[v][vf[v] >= 0]
        outside = int(np.flatnonzero(~np.isin(np.arange(mesh.n_faces), fan))[0])
        rows += [(v, a, b) for a in fan for b in [*fan, outside]]
    v, f_in, f_out = (jnp.asarray(c, jnp.int32) for c in zip(*rows))
    arc = jax.jit(jax.vmap(_smooth_repair.fan_arc, in_axes=(None, 0, 0, 0)))
    for m in (mesh, mesh.padded()):
        got = [np.asarray(x) for x in arc(m, v, f_in, f_out)]
        assert got[0].shape[-1] == m.vertex_faces.shape[1]
        for i, row in enumerate(rows):
            want = walk_across_edges(m, *row)
            for g, w in zip(got, want):
                np.testing.assert_array_equal(g[i], w, err_msg=str(row))
        # ways that arrive: both round a closed fan, one along an open one, none
        # to a face outside the fan
        ways = got[3].sum(axis=1)
        closed = np.asarray(m.fan_closed)[np.asarray(v)]
        inside = np.array([b in vf[a] for a, _, b in rows])
        moved = inside & (np.asarray(f_in) != np.asarray(f_out))
        assert np.all(ways[moved] == np.where(closed, 2, 1)[moved])
        assert np.all(ways[~inside] == 0) and moved.sum() > len(rows) // 2
