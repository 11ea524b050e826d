"""The changing state of a run (hybrid.simulation.Simulation): set_state (a run started
from a state given by hand, checked at the door), the step count, Python schedules,
the compiled frame capture (step_frames), and membrane-only runs that never import MuJoCo."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import textwrap

import helpers
import numpy as np
import pytest
from helpers import BASE, with_force

import hybrid
from hybrid.demo import membrane_demo
from hybrid.errors import SceneError, SimulationDiverged
from hybrid.model import compile_scene
from hybrid.scene import Muscle
from hybrid.schedule import Function
from hybrid.simulation import Simulation


@pytest.fixture(scope="module")
def membrane_model():
    return hybrid.compile_scene(hybrid.load_scene("membrane_demo"))


@pytest.fixture(scope="module")
def trunk_model(breathing):
    return hybrid.compile_scene(breathing)


def _saved(sim):
    out = dict(vert_pos=sim.vert_pos.copy(), vert_vel=sim.vert_vel.copy(), time_s=sim.time)
    if sim.mj_data is not None:
        out.update(qpos=sim.mj_data.qpos.copy(), qvel=sim.mj_data.qvel.copy())
    return out


def test_a_membrane_state_set_by_hand_continues_the_run_to_the_bit(membrane_model):
    a = hybrid.Simulation(membrane_model)
    a.step(250)
    saved = _saved(a)
    b = hybrid.Simulation(membrane_model)
    b.step(40)  # whatever it did before is forgotten
    b.set_state(**saved)
    assert b.steps_done == a.steps_done == 250 and b.time == a.time
    assert np.array_equal(b.vert_pos, a.vert_pos) and np.array_equal(b.vert_vel, a.vert_vel)
    assert b.pressure == 0.0  # the last projection belonged to the old positions
    a.step(150)
    b.step(150)
    assert np.array_equal(b.vert_pos, a.vert_pos) and np.array_equal(b.vert_vel, a.vert_vel)
    assert b.time == a.time and b.pressure == a.pressure


def test_unset_parts_stay_and_the_arrays_are_copied(membrane_model):
    sim = hybrid.Simulation(membrane_model)
    sim.step(10)
    vel, t = sim.vert_vel.copy(), sim.time
    pos = sim.vert_pos + 1e-4
    expected = pos.copy()
    sim.set_state(vert_pos=pos)
    pos[:] = 0.0  # the caller's array is not the state
    assert np.array_equal(sim.vert_pos, expected)
    assert np.array_equal(sim.vert_vel, vel) and sim.time == t and sim.steps_done == 10


def test_a_failed_run_steps_again_from_a_state_set_by_hand(membrane_model):
    sim = hybrid.Simulation(membrane_model.with_dt(0.05))  # far beyond the stability bound
    with pytest.raises(hybrid.SimulationDiverged):
        sim.step(200)
    with pytest.raises(hybrid.SimulationDiverged):
        sim.step(1)  # refuses while the state is the failing one
    rest = hybrid.Simulation(membrane_model)
    sim.set_state(vert_pos=rest.vert_pos, vert_vel=rest.vert_vel, time_s=0.0)
    sim.step(1)
    assert sim.steps_done == 1 and np.all(np.isfinite(sim.vert_pos))


def test_a_projection_failing_after_it_held_is_a_divergence_and_at_the_first_step_the_surfaces_fault():
    from hybrid.scene import Gravity

    model = hybrid.compile_scene(helpers.base_scene(forces=(Gravity(),)))
    still = np.zeros((model.nvert, 3))
    # every point at one place, at rest: gravity moves the free points alike, so the volume
    # gradient on them vanishes and the projection fails
    for steps, error, words in (
        (
            3,
            hybrid.SimulationDiverged,
            ["diverged at t = 0.003 s", "projection failed", "surface folded", "m from rest", "try dt_s <="],
        ),
        (0, hybrid.ConstraintError, ["projection failed at t = 0 s", "closed surface"]),
    ):
        sim = hybrid.Simulation(model)
        sim.step(steps)
        sim.set_state(vert_pos=np.broadcast_to(sim.vert_pos.mean(axis=0), still.shape).copy(), vert_vel=still)
        with pytest.raises(error) as e:
            sim.step(1)
        assert all(w in str(e.value) for w in words) and "\n" not in str(e.value), str(e.value)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(vert_pos=np.zeros((79, 3))), ["vert_pos", "(80, 3)", "(79, 3)"]),
        (dict(vert_vel=np.zeros(240)), ["vert_vel", "(80, 3)", "(240,)"]),
        (dict(vert_vel=[[0.0, 0.0], [0.0]]), ["vert_vel", "(80, 3)", "ragged list"]),
        (dict(vert_pos="rest"), ["vert_pos", "(80, 3)", "'rest'"]),
        (dict(vert_vel=np.full((80, 3), np.inf)), ["vert_vel", "finite", "inf", "(0, 0)", "240 non-finite"]),
        (dict(time_s=-1.0), ["time_s", ">= 0", "-1.0"]),
        (dict(time_s=float("nan")), ["time_s", "finite", "nan"]),
        (dict(time_s="0"), ["time_s", "'0'"]),
        (dict(qpos=[0.1, 0.2]), ["qpos", "no rigid part", "(2,)"]),
        (dict(qvel=[0.0]), ["qvel", "no rigid part", "(1,)"]),
    ],
)
def test_bad_values_name_the_argument_what_was_expected_and_what_came(membrane_model, kwargs, words):
    sim = hybrid.Simulation(membrane_model)
    sim.step(5)
    before = _saved(sim)
    good = sim.vert_pos + 1e-3  # set along with the bad one: nothing is set when one is refused
    with pytest.raises(ValueError) as err:
        sim.set_state(**({"vert_pos": good} if "vert_pos" not in kwargs else {}), **kwargs)
    msg = str(err.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)
    after = _saved(sim)
    assert all(np.array_equal(before[k], after[k]) for k in before) and sim.steps_done == 5


def test_the_rigid_state_goes_through_mujoco_and_the_linked_points_follow(trunk_model):
    sim = hybrid.Simulation(trunk_model)
    m, d = sim.mj_model, sim.mj_data
    link = sim.model.link_vert
    site_id = sim.rigid.system.site_id
    qpos = d.qpos + 0.02  # both ribs raised by 0.02 rad about their hinges
    qvel = np.full(m.nv, 0.1)
    sim.set_state(qpos=qpos, qvel=qvel, time_s=0.5)
    assert np.array_equal(d.qpos, qpos) and np.array_equal(d.qvel, qvel)
    assert d.time == 0.5 and sim.time == 0.5 and sim.steps_done == 500
    # the derived quantities are those of the new state, and the linked points sit on their sites
    assert np.array_equal(sim.vert_pos[link], d.site_xpos[site_id])
    lift = sim.vert_pos[link, 2] - sim.model.mesh.vert_pos[link, 2]
    assert lift.mean() > 1e-3
    assert np.linalg.norm(sim.vert_vel[link], axis=1).min() > 0
    # replays start from the state set
    assert np.array_equal(sim.rigid.initial_state, sim.rigid.system.state())
    with pytest.raises(ValueError, match=r"qpos: expected finite values \(mj_model.nq = 2\) of shape \(2,\)"):
        sim.set_state(qpos=np.zeros(3))
    with pytest.raises(ValueError, match=r"qvel: expected finite values.*nan at index \(1,\)"):
        sim.set_state(qvel=[0.0, np.nan])
    sim.step(100)
    assert np.all(np.isfinite(sim.vert_pos))


def test_a_coupled_state_set_by_hand_continues_the_run(trunk_model):
    a = hybrid.Simulation(trunk_model)
    a.step(300)
    saved = _saved(a)
    b = hybrid.Simulation(trunk_model)
    b.set_state(**saved)
    assert np.array_equal(b.vert_pos, a.vert_pos) and np.array_equal(b.vert_vel, a.vert_vel)
    a.step(100)
    b.step(100)
    # the same run but for the one step of pressure the ribs do not receive (no projection yet)
    assert np.abs(b.vert_pos - a.vert_pos).max() < 1e-5  # m, against a rib lift of millimetres
    assert np.abs(b.mj_data.qpos - a.mj_data.qpos).max() < 1e-4  # rad
    assert b.pressure == pytest.approx(a.pressure, rel=1e-3)


def test_step_count_must_be_a_non_negative_integer():
    sim = Simulation(compile_scene(BASE))
    for n in (-1, 2.5, "10"):
        with pytest.raises(ValueError, match=r"n: expected an integer >= 0, received"):
            sim.step(n)
    assert sim.steps_done == 0


def test_a_python_schedule_returning_a_wrong_size_is_named():
    def contraction(t):
        return [1.0, 2.0]  # neither a number nor a 3-vector

    # issue 31: a function of the wrong size at t = 0 is refused with the scene, before a step
    with pytest.raises(SceneError, match=r"stiffness: expected a function returning a number, received 'contraction'"):
        compile_scene(with_force(Muscle("top", Function(contraction), toward_m=(0, 0, 0.12))))

    def later(t):
        return 1.0 if t == 0 else [1.0, 2.0]  # right at t = 0 s only: caught when called

    sim = Simulation(compile_scene(with_force(Muscle("top", Function(later), toward_m=(0, 0, 0.12)))))
    with pytest.raises(
        SimulationDiverged,
        match=r"schedule function 'later' returned \[1\.0, 2\.0\] at t = 0.001 s; expected 1 or 3 finite numbers",
    ):
        sim.step(1)


def test_step_frames_captures_the_state_at_each_stop():
    stops = [3, 10, 10, 17]
    sim, ref = hybrid.load(), hybrid.load()
    frames = sim.frames_buffer(8)
    sim.step_frames(stops, frames)
    assert frames.count == 4 and sim.steps_done == 17
    for i, stop in enumerate(stops):
        ref.step(stop - ref.steps_done)
        np.testing.assert_array_equal(frames.pos[i], ref.vert_pos)
        np.testing.assert_array_equal(frames.body_pos[i], ref.mj_data.xpos[1:])
        np.testing.assert_array_equal(frames.body_quat[i], ref.mj_data.xquat[1:])
        assert frames.scal[i, 0] == ref.time
        assert frames.scal[i, 1] == ref.volume
        assert frames.scal[i, 2] == ref.pressure
        assert frames.scal[i, 3] == ref.kinetic_energy


def test_step_frames_keeps_the_frames_before_a_divergence():
    scene = dataclasses.replace(membrane_demo(), dt_s=0.006)  # diverges at step 11
    sim, ref = hybrid.load(scene), hybrid.load(scene)
    frames = sim.frames_buffer(10)
    with pytest.raises(SimulationDiverged) as caught:
        sim.step_frames(np.arange(2, 21, 2), frames)
    with pytest.raises(SimulationDiverged) as expected:
        ref.step(20)
    assert caught.value.step == expected.value.step == 11
    assert frames.count == 5  # steps 2, 4, ..., 10
    assert sim.steps_done == ref.steps_done == 11
    with pytest.raises(SimulationDiverged):  # a failed simulation refuses to go on
        sim.step_frames([12], frames)
    assert frames.count == 0


@pytest.mark.parametrize(
    "stops, expected", [([5, 3], "increasing"), ([-1], "increasing"), (list(range(1, 12)), "capacity")]
)
def test_step_frames_refuses_bad_stops(stops, expected):
    sim = hybrid.load(membrane_demo())
    with pytest.raises(ValueError, match=expected):
        sim.step_frames(stops, sim.frames_buffer(10))


MEMBRANE_ONLY = textwrap.dedent("""\
    name = "membrane_only"
    formulation = "paper"
    dt_s = 1e-3
    [mesh]
    generator = "uv_sphere"
    [masses]
    total_kg = 4.0
    [regions]
    top = { half_space = { point = [0, 0, 0.07], normal = [0, 0, 1] } }
    base = { half_space = { point = [0, 0, -0.09], normal = [0, 0, -1] } }
    [[forces]]
    type = "shape_memory"
    stiffness_n_per_m = 3000.0
    [[forces]]
    type = "damping"
    critical_fraction = 0.3
    [[forces]]
    type = "muscle"
    region = "top"
    toward_m = [0, 0, 0.12]
    stiffness = { breathing = { peak = 60.0 } }
    [[constraints]]
    type = "nailed"
    region = "base"
    [[constraints]]
    type = "volume"
    """)


def test_membrane_only_scene_never_imports_mujoco_and_absent_terms_never_run(tmp_path):
    path = tmp_path / "membrane.toml"
    path.write_text(MEMBRANE_ONLY)
    code = textwrap.dedent(f"""\
        import sys
        from hybrid.scenefile import load_scene
        from hybrid.model import compile_scene
        from hybrid.simulation import Simulation
        scene = load_scene({str(path)!r})
        sim = Simulation(compile_scene(scene))
        sim.step(300)
        calls = sim.term_calls
        assert calls["muscle"] == 300 and calls["shape_memory"] == 300, calls
        lean = Simulation(compile_scene(scene.without("muscle")))
        lean.step(300)
        assert lean.term_calls["muscle"] == 0 and lean.term_calls["shape_memory"] == 300
        assert lean.term_calls["mass_spring"] == 0 and lean.term_calls["gravity"] == 0
        print("mujoco" in sys.modules, sim.rigid is None)
        """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["False", "True"]


def test_a_pickled_model_runs_the_compiled_loop_of_the_original(membrane_model):
    # a sweep's worker receives its model pickled, and numpy unpickles arrays writable: an
    # array's flag is part of the compiled loop's signature, so unless the model freezes its
    # arrays again the worker would compile the whole loop again (a minute on 2 cores)
    import pickle

    from hybrid.loop import run_steps

    first = Simulation(membrane_model)
    first.step(3)
    builds = len(run_steps.signatures)
    assert pickle.loads(pickle.dumps(membrane_model.arrays.vert_rest)).flags.writeable  # the premise
    back = pickle.loads(pickle.dumps(membrane_model))
    again = Simulation(back)
    again.step(3)
    assert len(run_steps.signatures) == builds
    np.testing.assert_array_equal(again.vert_pos, first.vert_pos)  # the same run, to the bit
