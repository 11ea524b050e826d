"""`hybrid.Control`: the inputs a step reads, set by the scene's schedules or by the
user's program between steps (issue 26)."""

import numpy as np
import pytest

import hybrid
from hybrid.model import compile_scene
from hybrid.regions import HalfSpace
from hybrid.scene import Damping, Masses, MeshSpec, Rigid, RigidLink, Scene, ShapeMemory
from hybrid.schedule import Table, evaluate
from hybrid.simulation import Simulation

TENSION = "forces['muscle'].tension_n_per_m"

# a torso fixed in space with a hinged arm driven by a motor (+-5 N m), the membrane on the torso
XML = """<mujoco><option timestep="0.002"/>
<worldbody><body name="torso" pos="0 0 1"><freejoint name="root"/><geom size="0.1" mass="5"/>
<body name="arm" pos="0.1 0 0"><joint name="shoulder" axis="0 1 0" damping="0.05"/>
<geom type="capsule" size="0.03" fromto="0 0 0 0.3 0 0" mass="1"/></body></body></worldbody>
<actuator><motor name="m_shoulder" joint="shoulder" ctrlrange="-5 5" ctrllimited="true"/></actuator></mujoco>"""


def _arm_scene(tmp_path, ctrl):
    path = tmp_path / "arm.xml"
    path.write_text(XML)
    return Scene(
        formulation="paper",
        mesh=MeshSpec(generator="icosahedron", radius_m=0.05, center_m=(0, 0, 1.0)),
        masses=Masses(total_kg=0.1),
        regions={"top": HalfSpace((0, 0, 1.02), (0, 0, 1))},
        forces=(ShapeMemory(100.0), Damping(critical_fraction=0.3)),
        rigid=Rigid(str(path), links=(RigidLink("top", "torso"),), fix_root=True, ctrl=ctrl),
        duration_s=1.0,
    )


def test_a_run_driven_through_control_with_its_schedules_values_is_the_scheduled_run():
    model = compile_scene(hybrid.load_scene("breathing", overrides=["mesh.level=0"]))
    scheduled = Simulation(model, build="serial")
    scheduled.step(300)
    sched = next(t for t in model.scene.forces if t.name == "muscle").tension_n_per_m
    driven = Simulation(model, build="serial")
    h = model.dt_s
    for k in range(300):  # step k runs from k h (hybrid.loop)
        driven.control.set(TENSION, evaluate(sched, k * h)[0])
        driven.step(1)
    assert driven.control.is_set(TENSION)
    for a, b in ((scheduled.vert_pos, driven.vert_pos), (scheduled.mj_data.qpos, driven.mj_data.qpos)):
        assert np.array_equal(a, b)
    # released, the input follows its schedule again
    driven.control.release(TENSION)
    driven.step(1)
    assert driven.control.value(TENSION) == evaluate(sched, 300 * h)[0]


def test_mujoco_ctrl_through_control_is_the_scheduled_ctrl_bit_for_bit(tmp_path):
    sched = Table((0.0, 0.1, 0.2), (0.0, 2.0, -1.0))
    model = compile_scene(_arm_scene(tmp_path, {"m_*": sched}))
    scheduled = Simulation(model)
    scheduled.step(80)
    driven = Simulation(model)
    key = "rigid.ctrl['m_shoulder']"
    assert key in driven.control.keys
    for k in range(80):
        driven.control.set(key, evaluate(sched, k * model.dt_s)[0])
        driven.step(1)
    assert np.array_equal(scheduled.mj_data.qpos, driven.mj_data.qpos)
    assert np.array_equal(scheduled.vert_pos, driven.vert_pos)


def test_a_pd_controller_in_user_code_holds_the_arm_at_its_target_angle(tmp_path):
    """Closed loop through MuJoCo's ctrl: a PID on the shoulder angle, set every step."""
    model = compile_scene(_arm_scene(tmp_path, {"m_*": 0.0}))
    sim = Simulation(model)
    key, target_rad = "rigid.ctrl['m_shoulder']", 0.3
    adr = sim.mj_model.joint("shoulder").qposadr[0]
    vadr = sim.mj_model.joint("shoulder").dofadr[0]
    h, integral = model.dt_s, 0.0
    for _ in range(int(1.5 / h)):
        err = target_rad - sim.mj_data.qpos[adr]
        integral += err * h
        sim.control.set(key, np.clip(60.0 * err - 4.0 * sim.mj_data.qvel[vadr] + 200.0 * integral, -5, 5))
        sim.step(1)
    # the integral term cancels the arm's weight (about 1.5 N m): no steady offset
    # (measured 1.2e-4 rad after 1.5 s, 0.038 rad after 0.5 s)
    assert abs(sim.mj_data.qpos[adr] - target_rad) < 0.002
    assert abs(sim.mj_data.qvel[vadr]) < 0.01


def test_bad_controls_are_refused_in_one_line():
    sim = Simulation(compile_scene(hybrid.load_scene("breathing", overrides=["mesh.level=0"])))
    with pytest.raises(
        hybrid.SceneError, match=r"control 'tension': not an input of this scene; expected one of \["
    ) as e:
        sim.control.set("tension", 1.0)
    assert TENSION in str(e.value) and "\n" not in str(e.value)
    for bad in (float("nan"), (1.0, 2.0, 3.0), "12", None):
        with pytest.raises(hybrid.SceneError, match=r"control .*: expected a finite number, received"):
            sim.control.set(TENSION, bad)
    assert not sim.control.is_set(TENSION)  # nothing set by a refused call
    sim.control.set(TENSION, np.float32(3.5))  # numpy scalars are numbers
    assert sim.control.value(TENSION) == 3.5


def test_the_trace_and_the_recording_keep_the_controls_that_ran(tmp_path):
    """The muscle's tension set by the user's program (an observer acting as a controller,
    between frames) is what the trace's `muscle_n_per_m` and the recording's channel say ran,
    frame by frame, not the scene's schedule; released, the schedule is recorded again."""
    from hybrid.record import Recorder

    sim = hybrid.load("breathing", overrides=["mesh.level=0"])
    key = "forces['muscle'].tension_n_per_m"
    sent = []

    def controller(sim, trace):  # after each frame's row: the next frame's steps read it
        k = len(sent)
        if k < 20:
            sim.control.set(key, 3.0 + k)
        else:
            sim.control.release(key)
        sent.append(3.0 + k if k < 20 else None)

    with Recorder(tmp_path / "run.mcap", sim) as rec:
        tr = hybrid.run(sim, 0.5, observers=[rec, controller], frame_dt_s=0.01)["trace"].arrays()
    column = tr["muscle_n_per_m"]
    assert column[0] == 0.0  # the start: the schedule's value at rest
    for k in range(1, 21):  # frame k ran with what the controller set after frame k - 1
        assert column[k] == sent[k - 1]
    scheduled = hybrid.load("breathing", overrides=["mesh.level=0"])
    want = hybrid.run(scheduled, 0.5, frame_dt_s=0.01)["trace"].arrays()["muscle_n_per_m"]
    assert np.array_equal(column[22:], want[22:])  # released: the schedule again
    data = hybrid.read(tmp_path / "run.mcap")
    assert np.array_equal(data["/muscle"]["value"], column[: len(data["/muscle"]["value"])])
