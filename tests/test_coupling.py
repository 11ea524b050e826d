"""The breathing trunk: the membrane coupled to MuJoCo ribs at step time (hybrid.coupling;
paper 3.5, figure 4).

What is checked, and against what:
- the built-in breathing scene meets the physiological targets of quiet breathing
  (diaphragm excursion 18 +/- 3 mm, lower chest wall 3-5 mm, a few cmH2O of
  intra-abdominal pressure) and the paper's mechanism (no volume constraint, no rib
  lift); figures are computed as `hybrid run` defines them;
- the compiled coupled step against a plain Python loop over the public pieces
  (RigidSystem's methods and the membrane phases): equal to roundoff;
- MuJoCo's part against MuJoCo alone: the recorded wrenches replayed by
  `mujoco.rollout` give the same rib trajectory (bitwise here; <= 1e-12 asked);
- each run steps its own copy of the MuJoCo model; the linked points' weight;
- a MuJoCo blow-up is an error."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hybrid import rigid
from hybrid.coupling import Coupling
from hybrid.errors import SimulationDiverged
from hybrid.model import compile_scene
from hybrid.scene import Gravity, Scene
from hybrid.simulation import Simulation
from hybrid.step import OK, S_PRESSURE, S_TIME, membrane_advance, membrane_forces
from hybrid.step_work import new_control

PERIOD_S = 4.0


def breathing_run(scene: Scene, duration_s: float, frame_steps: int = 10) -> dict:
    """Run `scene` and measure it the way `hybrid run` does: rib lift = cranial
    displacement of the linked points' centroid, apex = the free point highest at
    rest, rest return = largest vertex distance from rest at the end of the run."""
    model = compile_scene(scene)
    sim = Simulation(model)
    rest = model.mesh.vert_pos
    link = model.link_vert
    z = rest[:, 2].copy()
    z[model.arrays.vert_free == 0] = -np.inf
    apex = int(np.argmax(z))
    nframe = int(round(duration_s / scene.dt_s)) // frame_steps
    t, lift, descent, pressure, verr = (np.empty(nframe) for _ in range(5))
    for k in range(nframe):
        sim.step(frame_steps)
        pos = sim.state.vert_pos
        t[k] = sim.time
        lift[k] = (pos[link, 2].mean() - rest[link, 2].mean()) * 1e3 if link.size else 0.0
        descent[k] = -(pos[apex, 2] - rest[apex, 2]) * 1e3
        pressure[k] = sim.pressure
        verr[k] = sim.volume_rel_error
    rest_return = float(np.linalg.norm(sim.state.vert_pos - rest, axis=1).max() * 1e3)
    return dict(sim=sim, t=t, lift=lift, descent=descent, pressure=pressure, verr=verr, rest_return_mm=rest_return)


# ----------------------------------------------------------------- the breathing scene


def test_breathing_scene_is_the_papers_figure_4(breathing):
    model = compile_scene(breathing)
    assert model.nvert == 80 and model.mesh.nface == 156
    assert model.arrays.vert_mass.sum() == pytest.approx(4.0)
    assert breathing.dt_s == 1e-3 and breathing.duration_s == 12.0
    assert set(model.terms) >= {"shape_memory", "muscle", "damping", "volume"}
    # the border ring between diaphragm and abdomen rides on the ribs, half on each
    sys_ = model.rigid
    assert sorted(set(sys_.link_body)) == ["rib_left", "rib_right"]
    lp = model.mesh.vert_pos[model.link_vert]
    assert np.allclose(lp[:, 2], lp[0, 2]) and 0.05 < lp[0, 2] < 0.09
    left = np.array(sys_.link_body) == "rib_left"
    assert np.all(lp[left, 1] > 0) and np.all(lp[~left, 1] < 0) and left.sum() == (~left).sum()
    # the sites sit exactly on the linked points at rest
    np.testing.assert_allclose(sys_.site_pos(), lp, atol=1e-12)


def test_breathing_meets_the_quiet_breathing_targets(breathing):
    r = breathing_run(breathing, breathing.duration_s)
    lift = r["lift"].max()
    descent = r["descent"].max()
    # lower chest wall 3-5 mm (acceptance range 2-8), diaphragm 18 +/- 3 mm (10-25)
    assert 2.0 <= lift <= 8.0, lift
    assert 10.0 <= descent <= 25.0, descent
    # intra-abdominal pressure: a few hundred Pa (a few cmH2O), positive in inspiration
    assert 100.0 <= r["pressure"].max() <= 1000.0 and r["pressure"].min() > -20.0
    assert r["verr"].max() <= 1e-10
    # the ribs rise in every inspiration and come back after it
    for cycle in range(3):
        insp = (r["t"] > cycle * PERIOD_S) & (r["t"] <= cycle * PERIOD_S + 0.4 * PERIOD_S + 0.3)
        assert r["lift"][insp].max() >= 0.9 * lift
        end = np.argmin(np.abs(r["t"] - (cycle + 1) * PERIOD_S))
        assert abs(r["lift"][end]) < 0.05 * lift
    assert r["rest_return_mm"] < 0.05 * lift


def test_without_volume_the_ribs_lift_at_most_a_third(breathing):
    # one breath is enough: inspiration is where the ribs rise
    with_volume = breathing_run(breathing, PERIOD_S)["lift"].max()
    without = breathing_run(breathing.without("volume"), PERIOD_S)["lift"].max()
    assert with_volume > 2.0
    assert without <= with_volume / 3.0, (with_volume, without)


# ----------------------------------------------------------------- the coupled step


def python_coupled_steps(model, nstep):
    """The coupled step written plainly with public pieces (module docstring)."""
    from hybrid.implicit_work import no_implicit_work
    from hybrid.step_work import new_state, new_work

    system = model.rigid.fork()
    system.reset()
    state = new_state(model.arrays)
    work = new_work(model.arrays, state)
    imp = no_implicit_work(model.arrays)  # the explicit integrators' (empty)
    link = model.link_vert
    coupling = Coupling(model)  # only for the weight correction of the linked points
    extra = coupling.link_extra_force()
    state.vert_pos[link] = system.site_pos()
    control = new_control(model.arrays)
    for k in range(nstep):
        t = state.scal[S_TIME]
        membrane_forces(model.arrays, state, work, imp, control, t)
        force = work.vert_force[link] + state.scal[S_PRESSURE] * state.grad[link] + extra
        system.apply_point_forces(force)
        system.step()
        state.vert_pos[link] = system.site_pos()
        state.vert_vel[link] = system.site_vel()
        assert membrane_advance(model.arrays, state, work, imp, control, t, k) == OK
        state.scal[S_TIME] = t + model.arrays.dt
    return state, system


def test_compiled_coupled_step_equals_the_plain_python_loop(breathing):
    model = compile_scene(breathing)
    sim = Simulation(model)
    sim.step(700)  # into the inspiration: muscle, pressure and ribs all active
    state, system = python_coupled_steps(model, 700)
    assert sim.pressure > 50.0
    # the same arithmetic, up to the fused multiply-adds LLVM may form differently
    # once the kernels are inlined into one function: roundoff, 1e-16 m per step
    np.testing.assert_allclose(sim.state.vert_pos, state.vert_pos, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sim.state.vert_vel, state.vert_vel, rtol=0, atol=1e-9)
    np.testing.assert_allclose(sim.rigid.mj_data.qpos, system.data.qpos, rtol=0, atol=1e-12)


def test_linked_points_ride_on_their_sites_and_step_by_step_equals_chunks(breathing):
    model = compile_scene(breathing)
    a, b = Simulation(model), Simulation(model)
    for _ in range(50):
        a.step(1)
    b.step(50)
    # times t0 + k h against sums of h: the schedules differ by roundoff only
    np.testing.assert_allclose(a.state.vert_pos, b.state.vert_pos, rtol=0, atol=1e-15)
    sites = a.rigid.mj_data.site_xpos[a.rigid.system.site_id]
    np.testing.assert_array_equal(a.state.vert_pos[model.link_vert], sites)
    # two simulations of one model do not share MuJoCo data
    assert a.rigid.mj_data is not b.rigid.mj_data
    a.reset()
    np.testing.assert_allclose(a.state.vert_pos, model.mesh.vert_pos, rtol=0, atol=1e-15)  # sites: roundoff
    assert a.rigid.mj_data.time == 0.0


def test_each_run_steps_its_own_copy_of_the_models_mujoco_model(breathing):
    model = compile_scene(breathing)
    a, b = Simulation(model), Simulation(model)
    pristine = model.rigid.model
    assert a.mj_model is not pristine and a.mj_model is not b.mj_model
    rib = pristine.body("rib_left").id
    mass0, dt0 = float(pristine.body_mass[rib]), float(pristine.opt.timestep)
    a.mj_model.body_mass[rib] *= 2.0
    a.mj_model.opt.timestep = 0.5 * dt0
    for other in (pristine, b.mj_model, Simulation(model).mj_model):
        assert other.body_mass[rib] == mass0 and other.opt.timestep == dt0
    # the copy changes no result: the run's ribs are MuJoCo's own on the Model's MjModel
    b.rigid.record_wrenches = True
    b.step(500)
    replay = rigid.replay_wrenches(pristine, b.rigid.initial_state, b.rigid.wrench_history())
    np.testing.assert_array_equal(replay, b.rigid.qpos_history())


def test_replaying_the_recorded_wrenches_through_mujoco_alone_gives_the_rib_trajectory(breathing):
    sim = Simulation(compile_scene(breathing))
    sim.rigid.record_wrenches = True
    sim.step(1000)
    sim.step(1)  # chunks append
    for _ in range(4):
        sim.step(250)
    xfrc = sim.rigid.wrench_history()
    qpos = sim.rigid.qpos_history()
    assert xfrc.shape == (2001, sim.rigid.mj_model.nbody, 6) and qpos.shape[0] == 2001
    assert np.abs(qpos).max() > 1e-3  # the ribs did move (rad)
    np.testing.assert_array_equal(qpos[-1], sim.rigid.mj_data.qpos)
    replay = rigid.replay_wrenches(sim.rigid.mj_model, sim.rigid.initial_state, xfrc)
    assert np.abs(replay - qpos).max() <= 1e-12


def test_mujoco_steps_with_the_membranes_step(breathing):
    model = compile_scene(breathing)
    assert model.rigid.model.opt.timestep == breathing.dt_s
    half = Simulation(model.with_dt(5e-4))
    assert half.rigid.mj_model.opt.timestep == 5e-4 and model.rigid.model.opt.timestep == 1e-3
    half.step(2000)
    assert half.rigid.mj_data.time == pytest.approx(1.0) and half.time == pytest.approx(1.0)


def test_linked_points_weigh_what_the_scene_says(breathing):
    model = compile_scene(breathing)
    sim = Simulation(model)
    g = np.array(sim.rigid.mj_model.opt.gravity)
    # no gravity term in the scene: what MuJoCo applies to the added masses is taken back
    np.testing.assert_allclose(sim.rigid.link_extra_force(), -model.rigid.link_mass[:, None] * g[None, :], rtol=1e-15)
    with_gravity = compile_scene(dataclasses.replace(breathing, forces=breathing.forces + (Gravity(),)))
    assert np.abs(Simulation(with_gravity).rigid.link_extra_force()).max() == 0.0


def test_a_mujoco_blow_up_is_an_error_not_a_silent_reset(breathing, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo writes MUJOCO_LOG.TXT where it runs
    scene = dataclasses.replace(breathing, rigid=dataclasses.replace(breathing.rigid, add_link_mass=False))
    sim = Simulation(compile_scene(scene))
    mjm = sim.rigid.mj_model  # ribs a thousand times lighter than the points they carry
    for name in ("rib_left", "rib_right"):
        b = mjm.body(name).id
        mjm.body_mass[b] *= 1e-3
        mjm.body_inertia[b] *= 1e-3
    with pytest.raises(SimulationDiverged, match="MuJoCo reset it"):
        sim.step(3000)
