"""Sliding links (`RigidLink.slide_stiffness_n_per_m3`): a point held to a plane its body carries,
free in the plane, as the diaphragm's zone of apposition slides along the inner rib cage.

What is checked, and against what:
- the plane's force is minus the gradient of its energy 1/2 k g^2 (central differences), zero
  for a displacement in the plane, and its reaction on the body is equal and opposite on the
  same line of action (net force and moment of the pair zero about any point, to roundoff);
- in the coupled breathing trunk the points slide along the ribs by centimetres while their
  gap from the planes stays at the penalty's p / stiffness; the bodies' wrenches are the
  opposite of the planes' forces; a run split through a saved state is bit for bit the run
  in one piece (tests/test_state.py);
- implicit Euler holds the planes in its Newton solve (tests/test_slide_planes_implicit.py: its
  matrix, forces and potential): above symplectic Euler's stable step the gap stays the
  penalty's and the volume exact, and its breath agrees with symplectic Euler's at a small step
  within its first-order error;
- the scene file's key round-trips, bad values are refused in one line, and the stable-step
  estimate counts the planes' stiffness."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

import hybrid
from hybrid.errors import SceneError
from hybrid.loads import Loads
from hybrid.loop import SlideArrays, slide_forces
from hybrid.mesh.geometry import vertex_area
from hybrid.scenefile import scene_from_dict, scene_to_toml
from hybrid.simulation import Simulation

K_N_PER_M3 = 1e7


def _sliding(k=K_N_PER_M3, *sets):
    links = [f"rigid.links.{n}.slide_stiffness_n_per_m3={k}" for n in ("rib_left", "rib_right")]
    return hybrid.load_scene("breathing", overrides=["mesh.level=0", *links, *sets])


def _rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def test_the_planes_force_is_minus_its_energys_gradient_and_its_reaction_opposite():
    rng = np.random.default_rng(3)
    ns, nvert, nbody = 5, 7, 3
    vert = np.array([1, 2, 4, 5, 6], np.int32)
    site_id, site_body = np.arange(ns, dtype=np.int64), np.array([1, 1, 2, 2, 1], np.int64)
    stiffness = rng.uniform(10.0, 100.0, ns)
    site_xpos = rng.normal(size=(ns, 3)) * 0.1
    site_xmat = np.array([_rotation(rng).ravel() for _ in range(ns)])
    xipos = rng.normal(size=(nbody, 3)) * 0.1
    pos = rng.normal(size=(nvert, 3)) * 0.1

    def apply(x):
        sl = SlideArrays(vert, site_id, site_body, stiffness, np.zeros((ns, 3)))
        f, xfrc = np.zeros((nvert, 3)), np.zeros((nbody, 6))
        slide_forces(sl, site_xpos, site_xmat, xipos, x, f, xfrc)
        return f, xfrc, sl.force

    def energy(x):
        n = site_xmat[:, [2, 5, 8]]
        g = ((x[vert] - site_xpos) * n).sum(axis=1)
        return 0.5 * (stiffness * g * g).sum()

    f, xfrc, on_points = apply(pos)
    np.testing.assert_array_equal(f[vert], on_points)
    # central differences of a quadratic: exact but for roundoff (1e-7 relative at this step)
    eps = 1e-6
    for i in vert:
        for a in range(3):
            xp, xm = pos.copy(), pos.copy()
            xp[i, a] += eps
            xm[i, a] -= eps
            fd = -(energy(xp) - energy(xm)) / (2 * eps)
            assert fd == pytest.approx(f[i, a], rel=1e-7, abs=1e-12)
    # a displacement in each plane changes nothing
    moved = pos.copy()
    for j, i in enumerate(vert):
        n = site_xmat[j, [2, 5, 8]]
        t = np.cross(n, rng.normal(size=3))
        moved[i] += 0.05 * t / np.linalg.norm(t)
    np.testing.assert_allclose(apply(moved)[0], f, atol=1e-12 * np.abs(f).max())
    # each body takes minus its points' forces, at the points: the pair's net force and its
    # moment about any point c vanish (the body's moment is about xipos: shift it to c)
    c = rng.normal(size=3)
    for b in (1, 2):
        mine = vert[site_body == b]
        net_f = xfrc[b, :3] + f[mine].sum(axis=0)
        body_m = xfrc[b, 3:] + np.cross(xipos[b] - c, xfrc[b, :3])
        net_m = body_m + np.cross(pos[mine] - c, f[mine]).sum(axis=0)
        scale = np.abs(f).max()
        assert np.abs(net_f).max() <= 1e-13 * scale and np.abs(net_m).max() <= 1e-13 * scale


@pytest.fixture(scope="module")
def sliding_run():
    model = hybrid.compile_scene(_sliding())
    sim = Simulation(model)
    sys_ = sim.rigid.system
    rest = model.mesh.vert_pos[model.slide_vert]
    worst_gap, worst_slide, worst_p = 0.0, 0.0, 0.0
    for _ in range(6):
        sim.step(int(round(0.25 / model.dt_s)))
        d = sim.mj_data
        x = sim.state.vert_pos[model.slide_vert]
        a, n = d.site_xpos[sys_.slide_site_id], d.site_xmat[sys_.slide_site_id][:, [2, 5, 8]]
        g = ((x - a) * n).sum(axis=1)
        worst_gap = max(worst_gap, float(np.abs(g).max()))
        worst_slide = max(worst_slide, float(np.linalg.norm(x - rest, axis=1).max()))
        worst_p = max(worst_p, float(sim.pressure))
    return model, sim, worst_gap, worst_slide, worst_p


def test_the_zone_slides_along_the_ribs_and_keeps_to_them(sliding_run):
    model, sim, gap, slide, p = sliding_run
    assert model.slide_vert.size == 22 and model.link_vert.size == 0
    # free points now, their mass on the membrane, not on the ribs
    assert (model.arrays.vert_free[model.slide_vert] == 1).all()
    # the points move by centimetres along the planes (23.7 mm measured) ...
    assert slide > 0.01
    # ... and off them by the penalty's gap: a load of pressure p on the sheet over stiffness K; the
    # membrane's tension adds its own load, so allow ten times the abdominal pressure's (measured 0.009 mm
    # against p / K = 0.017 mm at p = 166 Pa)
    assert 0 < gap <= 10 * p / K_N_PER_M3
    assert np.isfinite(sim.state.vert_pos).all()


def test_the_ribs_take_the_opposite_of_the_planes_forces(sliding_run):
    model, sim, *_ = sliding_run
    loads = Loads(sim)
    forces = loads.point_forces()
    slide = sim.rigid.slide_forces()
    for g in loads.groups:
        if g.kind == "body":
            assert g.slide_rows.size and not g.rows.size
            np.testing.assert_array_equal(forces[g.label], -slide[g.slide_rows])
            assert np.array_equal(g.vert, model.slide_vert[g.slide_rows])
    assert {g.name for g in loads.groups if g.kind == "body"} == {"rib_left", "rib_right"}


def test_the_key_round_trips_and_bad_values_are_refused():
    scene = _sliding()
    assert {k.slide_stiffness_n_per_m3 for k in scene.rigid.links} == {K_N_PER_M3}
    again = scene_from_dict(tomllib.loads(scene_to_toml(scene)))
    assert [k.slide_stiffness_n_per_m3 for k in again.rigid.links] == [K_N_PER_M3] * 2
    with pytest.raises(SceneError, match="slide_stiffness_n_per_m3") as err:
        _sliding(-1.0)
    assert "\n" not in str(err.value)


# implicit Euler at 3.5 ms: symplectic Euler's stable step with these planes is 2.25-2.5 ms (it runs
# at 2.25 and diverges at 2.5, below the estimate's 2.9); the solve holds the planes, but the bodies
# take their reaction explicitly (MuJoCo steps first), and the points' inertia on the light ribs
# (0.2 kg, against 0.5 kg of sliding points a rib) bounds the coupled step: 4.5 ms diverges (the
# partitioned coupling's added mass, hybrid.terms.slide_planes)
H_IMPLICIT = 0.0035
H_REFERENCE = 2.5e-4
SAMPLES = 8  # every 0.25 s of the first 2 s: the inspiration (1.6 s) and the start of expiration


def _breath(h, integrator):
    """(per sample: qpos, the sliding points' positions, pressure), the largest gap and volume error."""
    model = hybrid.compile_scene(_sliding(K_N_PER_M3)).with_dt(h, integrator)
    sim = Simulation(model)
    sys_ = sim.rigid.system
    out, gap, p, vol = [], 0.0, 0.0, 0.0
    for _ in range(SAMPLES):
        sim.step(int(round(0.25 / h)))
        d = sim.mj_data
        x = sim.state.vert_pos[model.slide_vert]
        a, n = d.site_xpos[sys_.slide_site_id], d.site_xmat[sys_.slide_site_id][:, [2, 5, 8]]
        gap = max(gap, float(np.abs(((x - a) * n).sum(axis=1)).max()))
        p = max(p, float(sim.pressure))
        vol = max(vol, sim.volume_rel_error)
        out.append((d.qpos.copy(), x.copy(), float(sim.pressure)))
    return out, gap, p, vol


@pytest.fixture(scope="module")
def implicit_runs():
    return {h: _breath(h, "implicit_euler") for h in (H_IMPLICIT, H_IMPLICIT / 2)}


def test_implicit_euler_holds_the_planes_above_the_explicit_step(implicit_runs):
    with pytest.raises(hybrid.SimulationDiverged):  # the step is above symplectic Euler's bound
        Simulation(hybrid.compile_scene(_sliding()).with_dt(H_IMPLICIT, "symplectic_euler")).step(100)
    _, gap, p, vol = implicit_runs[H_IMPLICIT]
    # the gap stays the penalty's, as in the symplectic run (0.0091 mm measured against p / K = 0.017 mm)
    assert 0 < gap <= 10 * p / K_N_PER_M3
    assert vol <= 1e-12


def test_implicit_euler_agrees_with_symplectic_euler_at_a_small_step(implicit_runs):
    ref = _breath(H_REFERENCE, "symplectic_euler")[0]
    coarse, fine = implicit_runs[H_IMPLICIT][0], implicit_runs[H_IMPLICIT / 2][0]

    def apart(one, other, k):
        return max(np.abs(np.asarray(a[k]) - np.asarray(b[k])).max() for a, b in zip(one, other))

    # implicit Euler is first order: its error at h is about twice its change from h to h / 2
    # (Richardson); allow 1.5 times that, plus the reference's own (14 times smaller a step,
    # its change from twice its step measured at 2e-6 of each value). Measured at the samples:
    # rib angles 3.3e-4 rad (1.2 times the change), sliding points 0.21 mm (1.4), pressure
    # 1.5 Pa (1.4): the bodies' explicit reaction lags a step
    for k, what in enumerate(("rib angles", "sliding points", "pressure")):
        size = max(np.abs(np.asarray(r[k])).max() for r in ref)
        err = apart(coarse, ref, k)
        assert err <= 3.0 * apart(coarse, fine, k) + 1e-6 * size, what
    # small against what moves: the ribs' lift (6.7 mrad) within 5% measured, the pressure 1%
    assert apart(coarse, ref, 0) <= 0.1 * max(np.abs(r[0]).max() for r in ref)
    assert apart(coarse, ref, 2) <= 0.02 * max(abs(r[2]) for r in ref)


def test_the_stable_step_counts_the_planes():
    soft, stiff = (hybrid.compile_scene(_sliding(k)) for k in (1e3, 1e11))
    # k = K x area on a point of mass m: a step of about 2 sqrt(m / k) at most
    area = vertex_area(soft.mesh.vert_pos, soft.mesh.face_vert)[stiff.slide_vert]
    m = stiff.arrays.vert_mass[stiff.slide_vert]
    bound = 2 * np.sqrt(m / (1e11 * area)).min()
    assert stiff.dt_stable_s <= bound < soft.dt_stable_s
