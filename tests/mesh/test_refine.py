"""Refinement of a closed mesh that is not a sphere: Loop subdivision against trimesh's,
and the levels of `refine_smooth` on the one smooth surface through the given points."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import hybrid
from hybrid.errors import MeshError
from hybrid.mesh.geometry import vertex_area
from hybrid.mesh.refine import (
    interpolating_control,
    loop_limit,
    loop_subdivide,
    refine_file_mesh,
    refine_smooth,
    split_faces,
)

#: the capsule of the tests: a cylinder 0.1 m long capped by hemispheres of radius 0.1 m,
#: 66 points (8 around, poles of 8 neighbours, rings of 5 and 6)
CAPSULE = dict(height=0.1, radius=0.1, count=[8, 8])
CAPSULE_VOLUME_M3 = np.pi * 0.1**2 * 0.1 + 4.0 / 3.0 * np.pi * 0.1**3


def capsule() -> tuple[np.ndarray, np.ndarray]:
    c = trimesh.creation.capsule(**CAPSULE)
    return np.array(c.vertices), np.array(c.faces)


def ellipsoid() -> tuple[np.ndarray, np.ndarray]:
    ico = hybrid.mesh.icosphere(1, 0.1)  # 42 points, twelve of five neighbours
    return ico.vert_pos * [1.0, 1.0, 1.5], np.array(ico.face_vert)


def test_loop_subdivision_is_trimeshs():
    """The same points and triangles as `trimesh.remesh.subdivide_loop` (numbered as
    `split_faces` numbers them): the same rules and weights, to round-off."""
    pos, face = ellipsoid()
    ours, our_face = loop_subdivide(pos, face, 2)
    ref, ref_face = trimesh.remesh.subdivide_loop(pos, face, 2)
    assert ours.shape == ref.shape and our_face.shape == ref_face.shape
    # each of our points is one of trimesh's (a few ulps of the 0.15 m body: sums in another order)
    dist, match = cKDTree(ref).query(ours)
    assert dist.max() < 1e-15 and len(set(match.tolist())) == len(ref)
    # and the triangles are trimesh's, as sets of its points
    assert {frozenset(t) for t in match[our_face].tolist()} == {frozenset(t) for t in ref_face.tolist()}
    # the topology is split_faces' own: only the positions differ
    np.testing.assert_array_equal(our_face, split_faces(pos, face, 2)[1])


def test_the_smooth_levels_keep_the_given_points_and_sample_one_surface():
    """The control points' limit positions are the given points (the interpolation holds),
    and each level holds the previous one's points: a point's limit position does not
    change when its control mesh is subdivided, so every level samples one surface."""
    pos, face = capsule()
    ctrl = interpolating_control(pos, face)
    size = np.ptp(pos, axis=0).max()
    # the solve's round-off: a few ulps of the body's size (the system's condition is about 4)
    assert np.abs(loop_limit(ctrl, face) - pos).max() < 1e-14 * size
    assert np.abs(ctrl - pos).max() > 1e-3  # the control mesh is not the file's: Loop moves points
    levels = [refine_smooth(pos, face, k) for k in range(4)]
    np.testing.assert_array_equal(levels[0][0], pos)
    for (coarse, _), (fine, fine_face) in zip(levels, levels[1:]):
        np.testing.assert_array_equal(fine[: len(pos)], pos)  # the file's points, exactly
        assert np.abs(fine[: len(coarse)] - coarse).max() < 1e-14 * size  # nested levels
        assert len(fine) == len(coarse) + 3 * len(fine_face) // 8  # one new point per edge: E = 3F/2
        assert hybrid.mesh.Mesh.from_arrays(fine, fine_face).volume() > 0  # valid, closed, outward


def test_the_smooth_levels_converge_at_second_order():
    """The levels' points are on a smooth surface (C2 but at points of other than six
    neighbours, C1 there) and their spacing halves a level: the inscribed polyhedron's
    volume and area approach the surface's at second order, each level's change 4 times
    the next one's (the next term of the error, a share h of it, moves the ratio by that
    share: 3.5 to 4.5 from level 1 on, measured 3.76, 3.94, 3.99 for the volume)."""
    pos, face = capsule()
    vols, areas = [], []
    for k in range(5):
        p, f = refine_smooth(pos, face, k)
        vols.append(hybrid.mesh.volume(p, f))
        areas.append(vertex_area(p, f).sum())
    for series in (vols, areas):
        d = np.diff(series)
        assert np.all(d > 0)  # the polyhedron grows toward the smooth surface it is inscribed in
        ratios = d[1:-1] / d[2:]
        assert np.all((3.5 < ratios) & (ratios < 4.5)), ratios
    # the limit (Richardson at order 2) is the capsule's own volume to within the
    # interpolation's error at the coarse spacing, where the curvature jumps (cylinder to cap):
    # measured 0.33% above it
    limit = vols[-1] + (vols[-1] - vols[-2]) / 3.0
    assert abs(limit / CAPSULE_VOLUME_M3 - 1.0) < 0.01


def test_the_surface_through_the_points_is_the_sampled_shape_not_plain_loops_shrunk_one():
    """Plain Loop subdivision moves the coarse points: its levels approach a smooth surface
    shrunk from the file's (by a share of the coarse spacing over the curvature radius,
    about a quarter of the volume here: measured 24% for the ellipsoid, 23% for the
    capsule), while the surface through the points is off only by the interpolation's
    error (0.2%, 0.3%). A factor of 10 between the two is far from both."""
    for (pos, face), exact in (
        (ellipsoid(), 4.0 / 3.0 * np.pi * 0.1**3 * 1.5),
        (capsule(), CAPSULE_VOLUME_M3),
    ):
        smooth = hybrid.mesh.volume(*refine_smooth(pos, face, 4))
        plain = hybrid.mesh.volume(*loop_subdivide(pos, face, 4))
        assert abs(smooth / exact - 1.0) < 0.1 * abs(plain / exact - 1.0), (smooth / exact, plain / exact)


def test_a_file_mesh_refines_onto_its_sphere_or_its_smooth_surface():
    sphere = hybrid.mesh.icosphere(1, 0.12)
    pos, face, scheme = refine_file_mesh(sphere.vert_pos, sphere.face_vert, 2)
    assert scheme == "sphere"
    np.testing.assert_allclose(np.linalg.norm(pos, axis=1), 0.12, rtol=1e-14)
    pos, face, scheme = refine_file_mesh(*capsule(), 1)
    assert scheme == "loop" and len(pos) == 66 + 3 * len(face) // 8


def test_an_open_file_mesh_off_a_sphere_is_refused_in_one_line():
    pos, face = capsule()
    top = np.flatnonzero(pos[face].mean(axis=1)[:, 2] < 0.1)  # the capsule without its top cap
    used = np.unique(face[top])
    index = np.full(len(pos), -1)
    index[used] = np.arange(len(used))
    with pytest.raises(MeshError, match=r"^mesh.level: expected a closed surface .* received an open surface "):
        refine_file_mesh(pos[used], index[face[top]], 1)
    with pytest.raises(MeshError, match="closed surface"):
        loop_subdivide(pos[used], index[face[top]], 1)
