"""Regions of physical size (issue 11, item 6): a `Patch` is the disc of the surface
within radius_m of the surface point nearest to its centre; its cells' area must be
pi r^2 within a rim of one edge length, or the region is refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

import hybrid
from hybrid.errors import SceneError
from hybrid.mesh import Mesh, icosphere, uv_sphere, vertex_area
from hybrid.regions import Difference, Patch, nearest_surface_point, select
from hybrid.scene import Masses, Nailed, Scene, Volume

R = 0.1
FAMILIES = {
    "icosphere": [icosphere(k, R) for k in (2, 3, 4)],
    "uv_sphere": [uv_sphere(R, s, s // 2) for s in (16, 32, 64)],
}


def _select(mesh, sel, name="patch"):
    return select(sel, mesh.vert_pos, name=name, border_vert=mesh.border_vert, face_vert=mesh.face_vert)


@pytest.mark.parametrize("family", FAMILIES)
def test_a_patch_covers_pi_r_squared_on_every_mesh(family):
    """A patch of radius 3 cm centred 2 cm off the sphere (its nearest surface point,
    not a vertex): area within the rim of one edge, and closer to pi r^2 as the
    mesh refines. On a sphere the area a ball of radius r centred on the surface
    cuts from it is 2 pi R (r^2 / 2R) = pi r^2 exactly."""
    r = 0.03
    direction = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    errs = []
    for mesh in FAMILIES[family]:
        idx = _select(mesh, Patch(tuple(1.2 * R * direction), r))
        q = nearest_surface_point(mesh.vert_pos, mesh.face_vert, 1.2 * R * direction)
        assert np.linalg.norm(q) == pytest.approx(R, rel=0.05)
        assert np.all(np.linalg.norm(mesh.vert_pos[idx] - q, axis=1) <= r)
        errs.append(abs(vertex_area(mesh.vert_pos, mesh.face_vert)[idx].sum() / (np.pi * r * r) - 1))
    assert errs[-1] < 0.1 and errs[-1] < errs[0], errs


def test_the_nearest_surface_point_lies_on_a_face_not_only_at_a_vertex():
    """A flat square of two triangles: the point above its middle projects to it."""
    mesh = Mesh.from_arrays(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]), np.array([[0, 1, 2], [0, 2, 3]]))
    np.testing.assert_allclose(nearest_surface_point(mesh.vert_pos, mesh.face_vert, (0.3, 0.6, 2.0)), [0.3, 0.6, 0])
    np.testing.assert_allclose(nearest_surface_point(mesh.vert_pos, mesh.face_vert, (2.0, 0.5, 1.0)), [1, 0.5, 0])


@pytest.mark.parametrize("family", FAMILIES)
def test_a_patch_larger_than_the_body_is_refused_naming_it(family):
    mesh = FAMILIES[family][1]
    with pytest.raises(
        SceneError,
        match=r"region 'pubis': a patch of radius_m = 0.3 m covers 0.12\d* m\^2 of this "
        r"mesh, expected pi r\^2 = 0.2827 m\^2 within .* m\^2 \(a rim of one edge "
        r"length, .* m\); widen the patch or refine the mesh",
    ) as err:
        _select(mesh, Patch((0.0, 0.0, -R), 0.3), "pubis")
    assert "\n" not in str(err.value)


def test_a_patch_cut_by_the_border_of_an_open_sheet_is_refused():
    n = 20
    x = np.linspace(0.0, 1.0, n + 1)
    gx, gy = np.meshgrid(x, x, indexing="ij")
    pos = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    k = np.arange(n * (n + 1)).reshape(n, n + 1)[:, :n].ravel()
    face = np.concatenate([np.stack([k, k + n + 1, k + n + 2], 1), np.stack([k, k + n + 2, k + 1], 1)])
    sheet = Mesh.from_arrays(pos, face)
    assert _select(sheet, Patch((0.5, 0.5, 0.1), 0.3)).size > 0  # inside: accepted
    with pytest.raises(SceneError, match=r"region 'edge': a patch of radius_m = 0.3 m covers"):
        _select(sheet, Patch((0.0, 0.5, 0.0), 0.3), "edge")  # half of it off the sheet


def test_a_patch_in_a_scene_and_its_file():
    """A nail of physical size in a continuum scene, inside a difference; through the scene file."""
    scene = Scene(
        mesh=hybrid.MeshSpec(generator="icosphere", subdivisions=3, radius_m=R),
        masses=Masses(total_kg=1.0),
        regions={"pubis": Difference(Patch((0.0, 0.0, -0.15), 0.02), Patch((0.0, 0.0, 0.15), 0.02))},
        constraints=(Nailed("pubis"), Volume()),
    )
    model = hybrid.compile_scene(scene)
    assert 3 <= model.regions["pubis"].size <= 40
    back = hybrid.scenefile.scene_from_dict(hybrid.scenefile.scene_to_dict(scene))
    assert back.regions == scene.regions
    with pytest.raises(SceneError, match=r"regions.pin.patch.radius_m: expected a number > 0, received -1"):
        hybrid.scenefile.scene_from_dict(
            {
                "mesh": {"generator": "icosahedron"},
                "masses": {"total_kg": 1.0},
                "regions": {"pin": {"patch": {"center": [0, 0, 1], "radius_m": -1}}},
            }
        )
