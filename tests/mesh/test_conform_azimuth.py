"""Columns of points at given azimuths (`mesh.conform_azimuth_deg`) and the wedge regions
they bound: a border that is edges of the mesh at every level, and a mesh that is
mirror-symmetric about the mid-sagittal plane where the azimuths are."""

from __future__ import annotations

import numpy as np
import pytest

from hybrid.errors import MeshError, SceneError
from hybrid.mesh.spheres import level_counts, ring_sphere, uv_sphere
from hybrid.regions import Wedge, select

AZIMUTHS_DEG = (5.0, 155.0, 165.0, -165.0, -155.0, -5.0)


def _border_columns(mesh, az_deg):
    """For each azimuth: the points on its half-plane (signed distance under 1e-12 of the
    radius) and the faces that cross it (points strictly on both sides)."""
    p, f = mesh.vert_pos, mesh.face_vert
    out = []
    for a in np.deg2rad(az_deg):
        d = p @ np.array([-np.sin(a), np.cos(a), 0.0])
        ahead = p @ np.array([np.cos(a), np.sin(a), 0.0]) > 0.0  # the half-plane, not its opposite
        on = ahead & (np.abs(d) < 1e-12)
        fd, fa = d[f], ahead[f].all(axis=1)
        cross = fa & (fd.max(axis=1) > 1e-12) & (fd.min(axis=1) < -1e-12)
        out.append((on, cross))
    return out


@pytest.mark.parametrize("level", [2, 4, 6])
def test_a_ring_sphere_has_a_column_of_points_at_each_azimuth_and_no_face_across_it(level):
    n = level_counts(level)[2]
    mesh = ring_sphere(n, 0.12, conform_z=(0.11, 0.08, 0.045, -0.05), conform_azimuth_deg=AZIMUTHS_DEG)
    z = mesh.vert_pos[:, 2]
    for on, cross in _border_columns(mesh, AZIMUTHS_DEG):
        # every circle between the pelvis and the tendon holds the column ...
        circles = np.unique(z[(z > -0.06) & (z < 0.09)])
        assert set(np.unique(z[on])) >= set(circles), level
        # ... so no face between them crosses the border (only near the poles, whose
        # circles are too small to hold every azimuth)
        centroid_z = mesh.vert_pos[mesh.face_vert[cross]][:, :, 2].mean(axis=1)
        assert np.all(np.abs(centroid_z) > 0.09), (level, np.sort(centroid_z))
    # mirror-symmetric about y = 0: each point's mirror image is a point (where the columns are)
    band = (z > -0.06) & (z < 0.09)
    mirror = mesh.vert_pos[band] * [1.0, -1.0, 1.0]
    d = np.linalg.norm(mirror[:, None, :] - mesh.vert_pos[None, band, :], axis=2).min(axis=1)
    assert d.max() < 1e-12


def test_a_uv_sphere_has_meridians_at_the_azimuths_and_keeps_its_counts():
    plain = uv_sphere(0.12, 52, 25)
    mesh = uv_sphere(0.12, 52, 25, conform_azimuth_deg=AZIMUTHS_DEG)
    assert mesh.nvert == plain.nvert and mesh.face_vert.shape == plain.face_vert.shape
    for on, cross in _border_columns(mesh, AZIMUTHS_DEG):
        assert on.sum() == 24 and cross.sum() == 0  # every circle, every face on one side
    np.testing.assert_array_equal(
        uv_sphere(0.12, 13, 7, conform_azimuth_deg=()).vert_pos, uv_sphere(0.12, 13, 7).vert_pos
    )


def test_conforming_azimuths_that_cannot_be_met_are_refused():
    with pytest.raises(MeshError, match="uv_sphere: 6 azimuths to conform to need segments >= 6; received 5"):
        uv_sphere(0.12, 5, 7, conform_azimuth_deg=AZIMUTHS_DEG)
    with pytest.raises(MeshError, match="ring_sphere: conform_azimuth_deg must be angles in \\[-360, 360\\] degrees"):
        ring_sphere(320, 0.12, conform_azimuth_deg=(5.0, 400.0))
    with pytest.raises(MeshError, match="at least two distinct azimuths"):
        ring_sphere(320, 0.12, conform_azimuth_deg=(5.0, -355.0))


def test_a_wedge_selects_by_azimuth_with_its_borders_and_across_180_degrees():
    az = np.deg2rad(np.arange(-175.0, 180.0, 10.0))  # points every 10 degrees, at -175 ... 175
    ring = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], axis=1) * 0.1
    pts = np.concatenate([ring, [[0.0, 0.0, 0.3]]])  # and one on the axis: no azimuth
    picked = lambda sel: np.rad2deg(az[select(sel, pts, name="w")]).round(6).tolist()  # noqa: E731
    assert picked(Wedge(5.0, 45.0)) == [5.0, 15.0, 25.0, 35.0, 45.0]  # borders included
    assert picked(Wedge(165.0, -165.0)) == [-175.0, -165.0, 165.0, 175.0]  # across 180
    assert picked(Wedge(-175.0, -175.0)) == [-175.0]
    assert len(picked(Wedge(0.0, 360.0))) == 36  # the whole turn, still not the axis
    # about the axis through x = 0.05 m: the points behind it (|azimuth| > 60 degrees about the
    # origin), and now the point above the origin, which is off that axis
    about = select(Wedge(90.0, 270.0, center=(0.05, 0.0, 0.0)), pts, name="w")
    assert about[-1] == len(az) and np.rad2deg(az[about[:-1]]).round(6).tolist() == [
        a for a in range(-175, 180, 10) if abs(a) > 60
    ]
    with pytest.raises(SceneError, match="region 'w': expected from_deg and to_deg in \\[-360, 360\\]"):
        select(Wedge(0.0, 720.0), pts, name="w")
