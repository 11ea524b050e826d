"""The rigid part's stable-step estimate (`hybrid.rigid.modes`) against MuJoCo's own steps."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from hybrid.cli import _warn_above_stable_step
from hybrid.model import compile_scene
from hybrid.resolve import resolve_scene
from hybrid.rigid.modes import rigid_modes

INERTIA = 0.003  # kg m^2 about the hinge
STIFFNESS = 12.0  # N m/rad


def _hinge(damping: float, integrator: str = "Euler", tendon_stiffness: float = 0.0) -> mujoco.MjModel:
    """One hinge of known inertia and spring (no gravity); with tendon_stiffness, a second one, its
    mirror, joined to it by a fixed tendon q1 - q2 (a spring on their difference only)."""
    body = """<body name="{n}" pos="{x} 0 0"><joint name="{n}_hinge" axis="0 1 0" stiffness="{k}" damping="{b}"/>
      <inertial pos="0 0 0" mass="1" diaginertia="{i} {i} {i}"/></body>"""
    bodies = body.format(n="a", x=0, k=STIFFNESS, b=damping, i=INERTIA)
    tendon = ""
    if tendon_stiffness:
        bodies += body.format(n="b", x=1, k=STIFFNESS, b=damping, i=INERTIA)
        tendon = f"""<tendon><fixed name="link" stiffness="{tendon_stiffness}">
          <joint joint="a_hinge" coef="1"/><joint joint="b_hinge" coef="-1"/></fixed></tendon>"""
    xml = f"""<mujoco><option gravity="0 0 0" integrator="{integrator}"/>
      <worldbody>{bodies}</worldbody>{tendon}</mujoco>"""
    return mujoco.MjModel.from_xml_string(xml)


def _amplitude_after(model: mujoco.MjModel, dt: float, q0, steps: int = 400) -> float:
    """The largest |qpos| over the steps; inf once MuJoCo finds its acceleration not finite (it
    then resets the state)."""
    model.opt.timestep = dt
    data = mujoco.MjData(model)
    data.qpos[:] = q0
    largest = 0.0
    for _ in range(steps):
        mujoco.mj_step(model, data)
        if data.warning[int(mujoco.mjtWarning.mjWARN_BADQACC)].number:
            return math.inf
        largest = max(largest, float(np.abs(data.qpos).max()))
    return largest


@pytest.mark.parametrize("damping", [0.0, 0.05, 0.5])
def test_a_hinge_s_stable_step_is_where_mujoco_s_euler_step_diverges(damping):
    modes = rigid_modes(_hinge(damping))
    omega = math.sqrt(STIFFNESS / INERTIA)
    assert modes.omega_rad_s == pytest.approx(omega, rel=1e-12)
    assert modes.damping_rate_per_s == pytest.approx(damping / INERTIA, rel=1e-12)
    if damping == 0.0:
        assert modes.dt_stable_s == pytest.approx(2.0 / omega, rel=1e-12)  # h omega < 2, symplectic Euler's
    # MuJoCo's own steps: 3% under the estimate they stay bounded (an undamped symplectic step keeps an
    # ellipse within 1 / sqrt(1 - (h omega / 2)^2) = 4.2 of the start at 0.97 of the limit), 3% over they
    # grow at least by 1.03 a step (the largest eigenvalue's modulus there), 400 steps: beyond 1e3
    assert _amplitude_after(_hinge(damping), 0.97 * modes.dt_stable_s, [0.1]) < 0.1 * 4.5
    assert _amplitude_after(_hinge(damping), 1.03 * modes.dt_stable_s, [0.1]) > 1e3
    assert modes.joints == ("a_hinge",)


def test_a_spring_between_two_hinges_limits_their_difference_s_mode():
    link = 40.0  # N m/rad on q1 - q2: the difference's mode has stiffness 12 + 2 x 40
    model = _hinge(0.0, tendon_stiffness=link)
    modes = rigid_modes(model)
    assert modes.omega_rad_s == pytest.approx(math.sqrt((STIFFNESS + 2 * link) / INERTIA), rel=1e-12)
    assert set(modes.joints) == {"a_hinge", "b_hinge"}
    # antisymmetric start: the fast mode alone
    assert _amplitude_after(model, 0.97 * modes.dt_stable_s, [0.1, -0.1]) < 0.45
    assert _amplitude_after(_hinge(0.0, tendon_stiffness=link), 1.03 * modes.dt_stable_s, [0.1, -0.1]) > 1e3


def test_rk4_s_limit_is_two_root_two_and_a_model_without_springs_has_none():
    modes = rigid_modes(_hinge(0.0, integrator="RK4"))
    assert modes.dt_stable_s == pytest.approx(2 * math.sqrt(2) / math.sqrt(STIFFNESS / INERTIA), rel=1e-12)
    free = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><joint type="hinge"/><geom size=".1"/></body></worldbody></mujoco>'
    )
    none = rigid_modes(free)
    assert math.isinf(none.dt_stable_s) and "none" in none.line(0.01)


def test_hybrid_run_warns_when_the_step_is_above_the_rigid_part_s_estimate(capsys):
    # the trunk with lungs' upper rib pair at the builder's damping: its sternal spring's mode at
    # 69.8 rad/s limits it to 0.0324 s (the realtime row's 0.03 s then folded after 2.1 s, the
    # pleural load added a step late); its own damping, 0.5 N m s/rad, puts the limit on the lower ribs
    base = ("integrator=implicit_euler", "rigid.ribs.pairs.0.damping_n_m_s_per_rad=0.05")
    warned = compile_scene(resolve_scene("breathing_lungs", overrides=(*base, "dt_s=0.035")))
    _warn_above_stable_step(warned)
    line = capsys.readouterr().err.strip()
    assert line.startswith("hybrid: warning: dt_s = 0.035 s is above the rigid stable-step estimate 0.0324 s")
    assert "upper_ribs_left_hinge, upper_ribs_right_hinge" in line and "\n" not in line
    quiet = compile_scene(resolve_scene("breathing_lungs", overrides=(*base, "dt_s=0.03")))
    _warn_above_stable_step(quiet)
    assert capsys.readouterr().err == ""
