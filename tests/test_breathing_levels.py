"""The breathing scene at any resolution (issue: a breathing trunk that converges): mesh
levels of two families, an anatomy of physical size on each, a file mesh equal to the
generated one, dt_s = "auto", and the diaphragm's swept volume."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import hybrid
from hybrid.errors import MeshError, SceneError
from hybrid.mesh import fibonacci_sphere, level_counts, uv_sphere, vertex_area
from hybrid.model import auto_dt, auto_dt_implicit, compile_scene, nice_floor
from hybrid.regions import select_faces
from hybrid.resolve import resolve_scene
from hybrid.run import run

ANATOMY = (
    "diaphragm",
    "abdomen",
    "rib_band",
    "tendon",
    "muscle",
    "rib_left_points",
    "rib_right_points",
    "pelvis",
    "spine",
)


def test_levels_start_at_the_papers_sphere_and_double_the_points():
    assert level_counts(0) == (13, 7, 80)
    counts = [level_counts(k)[2] for k in range(8)]
    assert all(1.75 < b / a < 2.25 for a, b in zip(counts, counts[1:])), counts
    with pytest.raises(MeshError, match="mesh level: expected an integer in \\[0, 16\\], received -1"):
        level_counts(-1)


def test_fibonacci_sphere_is_closed_outward_and_even():
    for n in (80, 631, 2518):
        m = fibonacci_sphere(n, 0.12)
        assert m.nvert == n and m.closed and m.volume() > 0
        # even cells: no pole fan (a UV sphere's pole cells are 1/S of its equator's)
        area = vertex_area(m.vert_pos, m.face_vert)
        assert area.max() / area.min() < 2.0, (n, area.max() / area.min())
        # the hull of points on the sphere: a polyhedron inside it, second-order close
        assert 4 / 3 * np.pi * 0.12**3 * (1 - 8.0 / n) < m.volume() < 4 / 3 * np.pi * 0.12**3
    uv = uv_sphere(0.12, 74, 35)
    a = vertex_area(uv.vert_pos, uv.face_vert)
    assert a.max() / a.min() > 10  # what the pole-free family avoids


@pytest.mark.parametrize("generator", ["ring_sphere", "uv_sphere", "fibonacci_sphere"])
def test_the_breathing_anatomy_exists_at_every_level(generator):
    # the fibonacci sphere has no circles to conform to: its regions' borders are jagged
    conform = ["mesh.conform_z_m=[]", "mesh.conform_azimuth_deg=[]"] if generator == "fibonacci_sphere" else []
    base = resolve_scene("breathing")
    area_mm2 = {}
    for level in range(6):
        sc = resolve_scene(base, overrides=[f"mesh.generator={generator}", f"mesh.level={level}", *conform])
        m = compile_scene(sc)
        assert abs(m.nvert - level_counts(level)[2]) <= 0.1 * level_counts(level)[2]
        if not conform:  # each conforming latitude is a circle of the mesh, at exactly its height
            for z in base.mesh.conform_z_m:
                assert np.count_nonzero(m.mesh.vert_pos[:, 2] == z) >= 3, (level, z)
        for name in ANATOMY:
            assert m.regions[name].size >= 1, (level, name)
        if generator == "ring_sphere" and level >= 2:
            # the ribs' attachments are mirror images (the mesh is symmetric where the columns are)
            left = m.mesh.vert_pos[m.regions["rib_left_points"]] * [1.0, -1.0, 1.0]
            right = m.mesh.vert_pos[m.regions["rib_right_points"]]
            assert left.shape == right.shape, (level, left.shape, right.shape)
            assert np.abs(left[np.lexsort(left.T)] - right[np.lexsort(right.T)]).max() < 1e-12, level
        # the regions are of physical size: the areas of their faces converge as the mesh refines
        p = m.mesh.vert_pos[m.mesh.face_vert]
        face_area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        area_mm2[level] = {
            name: face_area[select_faces(name, m.mesh.vert_pos, m.mesh.face_vert, sc.regions, name=name)].sum() * 1e6
            for name in ("diaphragm", "rib_band")
        }
    # a zone of a sphere of radius 0.12 m: 2 pi R dz. Conforming circles bound the faces
    # exactly (the polyhedron's area is second order: under 0.5% at level 5); the jagged
    # border of the fibonacci sphere is off by up to a row of faces
    tol = 0.15 if conform else 0.005
    for name, dz in (("rib_band", 0.035), ("diaphragm", 0.075)):
        exact = 2 * np.pi * 0.12 * dz * 1e6
        assert abs(area_mm2[5][name] - exact) < tol * exact, (name, area_mm2[5][name], exact)


def test_a_level_needs_a_generator_that_refines(tmp_path):
    with pytest.raises(SceneError, match="mesh.level: expected a generator that refines by level.*icosphere"):
        compile_scene(resolve_scene("breathing", overrides=["mesh.generator=icosphere"]))
    with pytest.raises(SceneError, match="mesh.conform_z_m: expected a generator with circles.*fibonacci_sphere"):
        compile_scene(resolve_scene("breathing", overrides=["mesh.generator=fibonacci_sphere"]))
    with pytest.raises(SceneError, match="mesh.conform_azimuth_deg: expected a generator with circles.*fibonacci"):
        compile_scene(resolve_scene("breathing", overrides=["mesh.generator=fibonacci_sphere", "mesh.conform_z_m=[]"]))


def test_the_scene_on_a_saved_level_4_mesh_runs_as_on_the_generated_one(tmp_path):
    generated = resolve_scene("breathing", overrides=["mesh.level=4"])
    model = compile_scene(generated)
    path = tmp_path / "level4.obj"
    model.mesh.save(path)
    from_file = dataclasses.replace(generated, mesh=dataclasses.replace(generated.mesh, path=str(path), level=None))
    model_file = compile_scene(from_file)
    np.testing.assert_array_equal(model_file.mesh.vert_pos, model.mesh.vert_pos)
    res = [run(hybrid.Simulation(m), 0.05)["summary"]["metrics"] for m in (model, model_file)]
    for key, v in res[0].items():  # 17 digits read back to the same doubles: the same run
        assert res[1][key]["max"] == pytest.approx(v["max"], rel=1e-9, abs=1e-15), key
    # a level on a file mesh splits its faces (about 4 times the points)
    assert (
        compile_scene(dataclasses.replace(from_file, mesh=dataclasses.replace(from_file.mesh, level=1))).nvert
        > 3 * model.nvert
    )


def test_auto_step_is_half_the_stable_estimate_rounded_down():
    assert [nice_floor(x) for x in (1e-3, 9.9e-4, 4.7e-4, 2.3e-4, 1.25e-4)] == [1e-3, 5e-4, 2e-4, 2e-4, 1e-4]
    for level in (0, 3):
        m = compile_scene(resolve_scene("breathing", overrides=[f"mesh.level={level}"]))
        assert m.dt_s == auto_dt(m.dt_stable_s) and m.dt_s <= 0.5 * m.dt_stable_s
        assert m.scene.dt_s == m.dt_s  # the model's scene holds the number the run uses
        assert m.rigid.model.opt.timestep == m.dt_s  # the ribs built for that step, not the probe's
    with pytest.raises(SceneError, match="dt_s"):
        compile_scene(resolve_scene("breathing", overrides=["dt_s=fast"]))
    # implicit Euler has no bound of its own: 4 times symplectic Euler's, at most 10 ms
    m = compile_scene(resolve_scene("breathing", overrides=["integrator=implicit_euler"]))
    explicit = m.with_dt(m.dt_s, "symplectic_euler").dt_stable_s
    # (rounded down to 1, 2 or 5 x 10^k, which loses at most a factor 2.5 of the 4)
    assert m.dt_s == auto_dt_implicit(explicit) and 1.6 * explicit <= m.dt_s <= min(4 * explicit, 0.01)
    assert m.rigid.model.opt.timestep == m.dt_s


def test_the_trace_gives_the_diaphragms_swept_volume():
    sim = hybrid.load("breathing", overrides=["mesh.level=1"])
    trace = run(sim, 0.5)["trace"].arrays()
    # the dome descends: it sweeps volume into the abdomen, as the simulation's readout says
    assert trace["swept_volume_ml"][-1] == pytest.approx(-sim.swept_volume_m3("diaphragm") * 1e6, rel=1e-12)
    assert trace["swept_volume_ml"][-1] > 1.0
    plain = hybrid.load(hybrid.Scene(forces=(hybrid.Membrane(youngs_modulus_n_per_m=100.0),)))
    assert np.isnan(run(plain, 0.01)["trace"].arrays()["swept_volume_ml"]).all()  # no diaphragm region


def test_a_sphere_read_from_a_file_refines_onto_its_sphere(tmp_path):
    from hybrid.mesh.refine import split_faces

    generated = resolve_scene("breathing", overrides=["mesh.level=1"])
    path = tmp_path / "level1.obj"
    compile_scene(generated).mesh.save(path)
    center = np.asarray(generated.mesh.center_m)
    areas = []
    for level in (1, 2, 3):
        m = compile_scene(
            dataclasses.replace(generated, mesh=dataclasses.replace(generated.mesh, path=str(path), level=level))
        )
        r = np.linalg.norm(m.mesh.vert_pos - center, axis=1)
        np.testing.assert_allclose(r, 0.12, rtol=1e-14)  # every new point on the sphere
        assert m.mesh.volume() > 0  # faces still outward (and the Mesh validated closed)
        areas.append(vertex_area(m.mesh.vert_pos, m.mesh.face_vert).sum())
    # the polyhedron's area tends to 4 pi R^2 at second order in the spacing (halved a level)
    err = [4 * np.pi * 0.12**2 - a for a in areas]
    assert all(e > 0 for e in err) and 3.5 < err[0] / err[1] < 4.5 and 3.5 < err[1] / err[2] < 4.5
    # without a projection the split keeps the polyhedron: the same area, the same volume
    coarse = compile_scene(generated).mesh
    pos, face = split_faces(coarse.vert_pos, coarse.face_vert, 2)
    assert vertex_area(pos, face).sum() == pytest.approx(
        vertex_area(coarse.vert_pos, coarse.face_vert).sum(), rel=1e-12
    )
    assert hybrid.mesh.volume(pos, face) == pytest.approx(coarse.volume(), rel=1e-12)


def test_a_level_of_a_closed_file_mesh_off_a_sphere_refines_through_its_points(tmp_path):
    """An ellipsoid (closed, off any sphere) refines by level toward the smooth surface
    through its points (`hybrid.mesh.refine.refine_smooth`): the file's points stay, numbered
    as in the file; an open surface off a sphere is refused in one line."""
    path = tmp_path / "ellipsoid.obj"
    ico = hybrid.mesh.icosphere(2, 0.1)
    hybrid.mesh.Mesh.from_arrays(ico.vert_pos * [1.0, 1.0, 1.3], ico.face_vert).save(path)
    sc = hybrid.Scene(
        mesh=hybrid.MeshSpec(path=str(path), level=1), forces=(hybrid.Membrane(youngs_modulus_n_per_m=100.0),)
    )
    m = compile_scene(sc)
    assert m.nvert == ico.nvert + 3 * ico.nface // 2 and m.mesh.name == "ellipsoid_level1"
    np.testing.assert_array_equal(m.mesh.vert_pos[: ico.nvert], ico.vert_pos * [1.0, 1.0, 1.3])
    assert compile_scene(dataclasses.replace(sc, mesh=hybrid.MeshSpec(path=str(path)))).nvert == ico.nvert
    lower = ico.vert_pos[ico.face_vert].mean(axis=1)[:, 2] < 0.05  # the ellipsoid without its top
    used = np.unique(ico.face_vert[lower])
    index = np.full(ico.nvert, -1)
    index[used] = np.arange(len(used))
    hybrid.mesh.Mesh.from_arrays(ico.vert_pos[used] * [1.0, 1.0, 1.3], index[ico.face_vert[lower]]).save(path)
    with pytest.raises(SceneError, match=r"mesh.level on a file mesh: expected a closed surface.*open surface"):
        compile_scene(sc)


def test_the_uv_and_ring_families_close_in_on_each_other():
    """The same anatomy on the UV family and on the pole-free ring family through the
    first inspiration: refined from level 2 to level 5 (8 times the points), the two
    families' metrics come closer, by at least half for every metric, and at level 5
    they are within 2% (the size of level 5's own error, CHANGELOG.md). Measured: 3.8, 4.6,
    4.7 and 9.1% apart at level 2; 1.1, 0.7, 0.9 and 1.6% at level 5."""
    keys = ("rib_lift_mm", "apex_descent_mm", "pressure_pa", "swept_volume_ml")

    def maxima(*sets):
        table = run(hybrid.load("breathing", overrides=list(sets)), 1.7)["summary"]["metrics"]
        return np.array([table[k]["max"] for k in keys])

    apart = {
        lv: np.abs(maxima(f"mesh.level={lv}", "mesh.generator=uv_sphere") / maxima(f"mesh.level={lv}") - 1.0)
        for lv in (2, 5)
    }
    assert np.all(apart[5] < 0.5 * apart[2]) and np.all(apart[5] < 0.02), dict(zip(keys, zip(apart[2], apart[5])))
