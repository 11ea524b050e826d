"""Regions given on a file mesh's points (`Indices`) carried through `mesh.level`: the
refinement map (each new point's parent edge, each face's parent face) is exact, and a
region's faces on the fine mesh are those inside its faces on the file's mesh, so that a
partition stays a partition at every level."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import hybrid
from hybrid.mesh.refine import refinement_of, split_faces
from hybrid.regions import Difference, Indices
from hybrid.scene import Masses, Membrane, MeshSpec, Nailed, Scene, Volume


def _coarse():
    c = trimesh.creation.capsule(height=0.1, radius=0.1, count=[8, 8])
    return np.asarray(c.vertices, float), np.asarray(c.faces, np.int64)


@pytest.mark.parametrize("level", [1, 3])
def test_the_refinement_map_is_the_split_s_own(level):
    """Split without moving the new points (planar): each new point is its parents'
    midpoint, and each fine face's corners are convex combinations of its parent face's
    corners (barycentric weights in [0, 1] summing to 1, to rounding)."""
    pos0, face0 = _coarse()
    pos, face = split_faces(pos0, face0, level)
    ref = refinement_of(pos0, face0, level)
    assert len(ref.vert_parent) == len(pos) - len(pos0) and len(ref.face_parent) == len(face)
    for start, end in zip(ref.level_start, (*ref.level_start[1:], len(pos))):
        a, b = ref.vert_parent[start - len(pos0) : end - len(pos0)].T
        assert (a < start).all() and (b < start).all()
        assert np.allclose(pos[start:end], 0.5 * (pos[a] + pos[b]), rtol=0, atol=1e-15)
    tri = pos0[face0[ref.face_parent]]  # (nface, 3 corners, 3): each fine face's parent face
    edges = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]], axis=2)  # (nface, 3, 2)
    normal = np.einsum("fij,fik->fjk", edges, edges)
    for k in range(3):
        rel = pos[face[:, k]] - tri[:, 0]
        uv = np.linalg.solve(normal, np.einsum("fij,fi->fj", edges, rel)[..., None])[..., 0]
        assert np.allclose(np.einsum("fij,fj->fi", edges, uv), rel, rtol=0, atol=1e-15)  # in its plane
        assert (uv > -1e-12).all() and (uv.sum(axis=1) < 1 + 1e-12).all()  # inside it


def _scene(folder, level):
    pos0, face0 = _coarse()
    hybrid.mesh.Mesh.from_arrays(pos0, face0, name="capsule").save(folder / "capsule.obj")
    top = tuple(int(i) for i in np.nonzero(pos0[:, 2] > 0.02)[0])  # given by the file's points
    return Scene(
        formulation="continuum",
        name="capsule_regions",
        mesh=MeshSpec(path=str(folder / "capsule.obj"), level=level),
        masses=Masses(total_kg=1.0),
        regions={"top": Indices(top), "rest": Difference("all", "top")},
        forces=(
            Membrane(name="top_sheet", region="top", youngs_modulus_n_per_m=100.0),
            Membrane(name="rest_sheet", region="rest", youngs_modulus_n_per_m=200.0),
        ),
        constraints=(Nailed("rest"), Volume()),
        dt_s=1e-4,
    )


def test_a_region_of_the_file_s_points_keeps_its_faces_and_partition_at_every_level(tmp_path):
    """The file's points picked by index, at levels 0-2: the region's faces are those inside
    its faces on the file's mesh (its area the same at every level, to the refined surface's
    own change) and, with its complement, they cover every face once; its points are the
    file's own and the new points inside it, so that it does not reach across its border."""
    areas = []
    for level in range(3):
        sim = hybrid.load(_scene(tmp_path, level))
        m = sim.model
        top, rest = m.region_faces("top"), m.region_faces("rest")
        assert len(np.intersect1d(top, rest)) == 0 and len(top) + len(rest) == m.mesh.nface
        ref = m.mesh.refinement
        if level:
            coarse_top = hybrid.load(_scene(tmp_path, 0)).model.region_faces("top")
            assert np.array_equal(np.sort(np.unique(ref.face_parent[top])), np.sort(coarse_top))
        tri = m.mesh.vert_pos[m.mesh.face_vert[top]]
        areas.append(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
        pts = m.regions["top"]
        assert set(m.mesh.face_vert[top].ravel()) >= set(pts.tolist())  # no point off its faces
    # the smooth surface's area converges: each level's change smaller than the last
    assert abs(areas[2] - areas[1]) < abs(areas[1] - areas[0]) < 0.05 * areas[0]


def test_an_index_past_the_file_s_points_is_refused_in_one_line(tmp_path):
    scene = _scene(tmp_path, 1)
    bad = {**scene.regions, "top": Indices((0, 10_000))}
    with pytest.raises(hybrid.errors.SceneError) as err:
        hybrid.load(Scene(**{**scene.__dict__, "regions": bad}))
    assert "must lie in [0, 66)" in str(err.value) and "\n" not in str(err.value)


def test_regions_of_geometry_on_a_smooth_file_surface_are_taken_on_the_file_s_mesh(tmp_path):
    """A half-space region on the capsule (off a sphere: refined on the smooth surface through
    its points): at every level its faces are those inside its faces on the file's mesh (by the
    centroid rule there), so its border follows the file's edges and does not cut across the
    new faces; on a sphere's file mesh (refined on its sphere) the geometry is kept exact."""
    from hybrid.regions import HalfSpace

    scene = _scene(tmp_path, 0)
    regions = {"top": HalfSpace((0.0, 0.0, 0.02), (0.0, 0.0, 1.0)), "rest": Difference("all", "top")}
    coarse = hybrid.load(Scene(**{**scene.__dict__, "regions": regions})).model
    for level in (1, 2):
        m = hybrid.load(
            Scene(**{**scene.__dict__, "regions": regions, "mesh": MeshSpec(path=scene.mesh.path, level=level)})
        ).model
        assert m.mesh.refinement.carry_geometry
        top, rest = m.region_faces("top"), m.region_faces("rest")
        assert np.array_equal(np.unique(m.mesh.refinement.face_parent[top]), np.sort(coarse.region_faces("top")))
        assert len(np.intersect1d(top, rest)) == 0 and len(top) + len(rest) == m.mesh.nface
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=0.1)
    hybrid.mesh.Mesh.from_arrays(sphere.vertices, sphere.faces, name="ball").save(tmp_path / "ball.obj")
    ball = hybrid.load(
        Scene(**{**scene.__dict__, "regions": regions, "mesh": MeshSpec(path=str(tmp_path / "ball.obj"), level=2)})
    ).model
    assert not ball.mesh.refinement.carry_geometry
    z = ball.mesh.vert_pos[ball.regions["top"], 2]
    assert (z >= 0.02).all()  # the half-space itself, on every point of the finer sphere


def test_the_apex_of_a_refined_file_mesh_is_the_same_point_at_every_level(tmp_path):
    """The apex (`hybrid.observers.metrics.apex_vertex`, whose vertical the dome's descent is
    measured on) is the highest of the file's points, which keep their places at every level:
    on a box, the smooth surface through its points bulges above its flat top, so that new
    points stand higher than the file's, and the highest point of each level would be another."""
    from hybrid.model import compile_scene
    from hybrid.observers.metrics import apex_vertex

    box = trimesh.creation.box(extents=(0.2, 0.16, 0.1))
    hybrid.mesh.Mesh.from_arrays(np.asarray(box.vertices, float), np.asarray(box.faces, np.int64)).save(
        tmp_path / "box.obj"
    )
    places = []
    for level in (0, 1, 2):
        model = compile_scene(
            Scene(
                formulation="continuum",
                mesh=MeshSpec(path=str(tmp_path / "box.obj"), level=level),
                masses=Masses(total_kg=1.0),
                forces=(Membrane(youngs_modulus_n_per_m=100.0),),
                constraints=(Volume(),),
                dt_s=1e-4,
            )
        )
        pos = model.mesh.vert_pos
        apex = apex_vertex(model)
        assert apex < len(box.vertices)  # one of the file's points
        places.append(pos[apex])
        if level:
            assert pos[:, 2].max() > pos[apex, 2] + 1e-3  # m: a new point stands higher
    assert np.array_equal(places[0], places[1]) and np.array_equal(places[0], places[2])
