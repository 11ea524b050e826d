"""Validation of a triangle surface and its one-ring fans (hybrid.mesh.validate): every bad
input names its culprit; edges and fans have every property the step relies on."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import hemisphere, sphere_arrays, torus

from hybrid.errors import MeshError
from hybrid.mesh import Mesh, uv_sphere


def check_rings(m: Mesh):
    """Every ring property of the brief, checked one vertex at a time (slow reference)."""
    oriented = {tuple(np.roll(f, k)) for f in m.face_vert.tolist() for k in range(3)}
    incident = np.bincount(m.face_vert.ravel(), minlength=m.nvert)
    neighbours = [set() for _ in range(m.nvert)]
    for i, j in m.edge_vert.tolist():
        neighbours[i].add(j)
        neighbours[j].add(i)
    undirected_count = {}
    for f in m.face_vert.tolist():
        for k in range(3):
            e = tuple(sorted((f[k], f[(k + 1) % 3])))
            undirected_count[e] = undirected_count.get(e, 0) + 1
    for v in range(m.nvert):
        ring = m.ring_vert[m.ring_ptr[v] : m.ring_ptr[v + 1]].tolist()
        assert set(ring) == neighbours[v] and len(ring) == len(neighbours[v])
        pairs = list(zip(ring[:-1], ring[1:]))
        if m.ring_closed[v]:
            pairs.append((ring[-1], ring[0]))
            assert ring[0] == min(ring)
        else:
            assert (v, ring[-1], ring[0]) not in oriented
            # an open fan starts and ends on border edges
            assert undirected_count[tuple(sorted((v, ring[0])))] == 1
            assert undirected_count[tuple(sorted((v, ring[-1])))] == 1
            assert v in m.border_vert
        assert len(pairs) == incident[v]
        for p, q in pairs:
            assert (v, p, q) in oriented  # counter-clockwise around the outward normal


def test_rings_of_closed_meshes(closed_mesh):
    check_rings(closed_mesh)
    assert closed_mesh.ring_closed.all()
    assert closed_mesh.ring_ptr[-1] == 2 * len(closed_mesh.edge_vert)


def test_uv_sphere_ring_turns_counter_clockwise_seen_from_outside():
    m = uv_sphere()
    assert m.ring_vert[m.ring_ptr[0] : m.ring_ptr[1]].tolist() == list(range(1, 14))
    # vertex 1 (on +x): north pole, west (13), two below (14, 15), east (2)
    assert m.ring_vert[m.ring_ptr[1] : m.ring_ptr[2]].tolist() == [0, 13, 14, 15, 2]


def test_rings_of_an_open_mesh():
    m = hemisphere()
    assert not m.closed
    on_equator = np.flatnonzero(np.abs(m.vert_pos[:, 2]) < 1e-9)
    assert len(on_equator) == 13
    np.testing.assert_array_equal(m.border_vert, on_equator)
    np.testing.assert_array_equal(~m.ring_closed, np.isin(np.arange(m.nvert), on_equator))
    check_rings(m)


def test_rings_of_a_single_triangle():
    m = Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    assert not m.closed and not m.ring_closed.any()
    np.testing.assert_array_equal(m.ring_ptr, [0, 2, 4, 6])
    np.testing.assert_array_equal(m.ring_vert, [1, 2, 2, 0, 0, 1])
    np.testing.assert_array_equal(m.border_vert, [0, 1, 2])


def test_edges_are_unique_sorted_pairs(closed_mesh):
    e = closed_mesh.edge_vert
    assert e.dtype == np.int32 and e.shape == (3 * closed_mesh.nface // 2, 2)
    assert np.all(e[:, 0] < e[:, 1])
    key = e[:, 0].astype(np.int64) * closed_mesh.nvert + e[:, 1]
    assert np.all(np.diff(key) > 0)  # lexicographic and unique


def test_torus_topology():
    m = torus()
    assert m.closed and m.nvert - len(m.edge_vert) + m.nface == 0  # genus 1


def corrupt(kind):
    """Sphere arrays with one defect; returns (vert_pos, face_vert)."""
    pos, face = sphere_arrays()
    if kind == "vert_shape":
        return pos[:, :2], face
    if kind == "vert_dtype":
        return pos.astype(complex), face
    if kind == "vert_ragged":
        return [[0, 0, 0], [1, 0]], face
    if kind == "nan":
        pos[5, 1] = np.nan
    elif kind == "inf":
        pos[7, 0] = np.inf
    elif kind == "face_dtype":
        face = face.astype(float)
    elif kind == "face_shape":
        face = np.concatenate([face, face[:, :1]], axis=1)
    elif kind == "face_range":
        face[3] = [0, 1, 80]
    elif kind == "face_negative":
        face[3] = [0, -1, 2]
    elif kind == "repeated_index":
        face[7] = [1, 1, 2]
    elif kind == "duplicate_face":
        face = np.concatenate([face, face[:1, ::-1]])
    elif kind == "duplicate_vertex":
        pos[10] = pos[3]
    elif kind == "unused_vertex":
        pos = np.concatenate([pos, [[5.0, 5.0, 5.0]]])
    elif kind == "zero_area":
        # a point in the middle of edge (0, 1) and a flat face along that edge
        pos = np.concatenate([pos, [(pos[0] + pos[1]) / 2]])
        face = np.concatenate([face, [[0, 80, 1]]])
    elif kind == "nonmanifold_edge":
        pos = np.concatenate([pos, [[0.0, 0.0, 2.0]]])
        face = np.concatenate([face, [[1, 0, 80]]])
    elif kind == "orientation":
        face[5] = face[5, ::-1]
    elif kind == "inward":
        face = face[:, ::-1]
    return pos, face


BAD = {
    "vert_shape": r"vert_pos must have shape \(nvert, 3\).*received shape \(80, 2\)",
    "vert_dtype": r"vert_pos .*received dtype complex128",
    "vert_ragged": r"vert_pos .*ragged",
    "nan": r"non-finite.*vertex 5 \[",
    "inf": r"non-finite.*vertex 7 \[",
    "face_dtype": r"face_vert .*integers; received dtype float64",
    "face_shape": r"face_vert must have shape \(nface, 3\).*received shape \(156, 4\)",
    "face_range": r"\[0, 80\).*face 3 \[0, 1, 80\]",
    "face_negative": r"\[0, 80\).*face 3 \[0, -1, 2\]",
    "repeated_index": r"repeat a vertex index: face 7 \[1, 1, 2\]",
    "duplicate_face": r"duplicate faces.*face 156 \[2, 1, 0\] repeats face 0 \[0, 1, 2\]",
    "duplicate_vertex": r"duplicate vertices.*vertex 10 repeats vertex 3",
    "unused_vertex": r"1 vertices are in no face: vertices 80",
    "zero_area": r"zero area: face 156 \[0, 80, 1\]",
    "nonmanifold_edge": r"non-manifold edges: edge \(0, 1\) in 3 faces \[0, 12, 156\]",
    "orientation": r"inconsistent face orientation.*faces? .*\b5 \[",
    "inward": r"inward-facing \(volume -\d.*flip the face orientation",
}


@pytest.mark.parametrize("kind", list(BAD))
def test_bad_input_names_the_culprit(kind):
    pos, face = corrupt(kind)
    with pytest.raises(MeshError, match=BAD[kind]) as info:
        Mesh.from_arrays(pos, face, name="bad")
    assert "mesh 'bad'" in str(info.value)


def test_many_culprits_are_counted():
    pos, face = sphere_arrays()
    pos[10:30, 0] = np.nan
    with pytest.raises(MeshError, match=r"20 vertices .*vertex 10 .*and 15 more"):
        Mesh.from_arrays(pos, face)


def test_open_bowtie_vertex_is_rejected():
    pos = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]]
    with pytest.raises(MeshError, match=r"non-manifold vertices.*vertex 0 \(2 fans"):
        Mesh.from_arrays(pos, [[0, 1, 2], [0, 3, 4]])


def test_closed_bowtie_vertex_is_rejected():
    # Two tetrahedra touching at vertex 0: every edge has two faces, yet vertex 0
    # has two closed fans.
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    tet_face = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    pos = np.concatenate([tet, -tet[1:]])  # point reflection: orientation flips
    mirrored = np.where(tet_face == 0, 0, tet_face + 3)[:, ::-1]
    face = np.concatenate([tet_face, mirrored])
    Mesh.from_arrays(tet, tet_face)  # each tetrahedron alone is fine
    with pytest.raises(MeshError, match=r"non-manifold vertices.*vertex 0 \(2 fans"):
        Mesh.from_arrays(pos, face)


def test_duplicate_vertex_from_negative_zero():
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [-0.0, 0, 0]])
    with pytest.raises(MeshError, match="vertex 3 repeats vertex 0"):
        Mesh.from_arrays(tri, [[0, 1, 2], [3, 2, 1]])
