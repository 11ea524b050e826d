"""The held volumes' pressures on the rigid bodies (hybrid.rigid.held_volumes): the occluded hold
shared with light ribs, the gain that estimates the growth per step where a hold is staggered
(RK4), and what a run, `hybrid inspect` and a divergence say of it."""

from __future__ import annotations

import numpy as np
import pytest

import hybrid
from hybrid.errors import SimulationDiverged
from hybrid.model import compile_scene
from hybrid.resolve import resolve_scene
from hybrid.rigid.held_volumes import held_volumes_gain, may_occlude
from hybrid.scenefile import apply_overrides
from hybrid.step_work import CALL_HOLD
from hybrid.studies.rigid_check import replay_check
from hybrid.terms.lungs import L_HOLD

PAIR = "rigid.ribs.pairs.0"


def light_ribs(mass_kg: float, *more: str):
    """`breathing_lungs` at level 0 with an undamped upper rib pair of mass_kg, the airway occluded."""
    return apply_overrides(
        resolve_scene("breathing_lungs"),
        [
            "mesh.level=0",
            f"{PAIR}.mass_kg={mass_kg}",
            f"{PAIR}.damping_n_m_s_per_rad=0",
            "forces.lungs.airway_occluded=1",
            *more,
        ],
    )


@pytest.mark.parametrize("mass_kg", [0.002, 0.0034])
def test_light_ribs_share_the_occluded_hold_and_keep_it(mass_kg):
    # Staggered, the occluded hold's pressure on these ribs grew 3.35-fold (2 g) and 1.93-fold
    # (3.4 g) a step, as the estimate said (3.05, 1.80), and the run diverged within 20 steps.
    # Shared (`hybrid.wall_coupling.hold_with_bodies`), the run holds the airway 1 s and its hold
    # is the 0.2 kg ribs': the packaged wall barely moves with the upper ribs, so their mass hardly
    # matters to the pressure (measured 0.04% apart); 1% of its swing would be a wrong hold.
    light, heavy = hybrid.load(light_ribs(mass_kg)), hybrid.load(light_ribs(0.2))
    hold = np.zeros((2, 1000))
    for k in range(hold.shape[1]):
        for row, sim in enumerate((light, heavy)):
            sim.step(1)
            hold[row, k] = sim.state.lung[L_HOLD]
    swing = np.abs(hold[1]).max()
    assert swing > 50.0  # Pa: the breath pulls on the held lungs
    assert np.abs(hold[0] - hold[1]).max() <= 0.01 * swing
    shared = held_volumes_gain(compile_scene(light_ribs(mass_kg)))
    staggered = held_volumes_gain(compile_scene(light_ribs(mass_kg, "rigid.integrator=RK4")))
    assert shared.occluded < 0.5 < 1.0 < staggered.occluded  # RK4's step is one call: staggered there
    assert shared.open == pytest.approx(staggered.open, rel=1e-12)  # the abdomen's hold is staggered in both


def test_an_occluded_run_on_light_ribs_replays_exactly():
    # the hold's change is a generalized force MuJoCo's second step takes (`qfrc_applied`),
    # recorded as the open airway's correction is: MuJoCo alone replays the run from it
    r = replay_check(light_ribs(0.002), 60)
    assert r["replay_max_abs_qpos"] <= 1e-12 and r["replay_max_abs_qvel"] <= 1e-12
    assert r["wrench_rel_error"] <= 1e-12 and r["qpos_moved_max"] > 1e-4


def test_the_hold_compiles_only_for_a_run_whose_airway_may_close():
    # a lungs scene breathing with its airway open never reaches the shared hold, and does not
    # compile it; the user's program closing the airway (`Control`) gets it before its next step:
    # light ribs, which a staggered hold diverged within 20 steps, then hold 300
    key = "forces['lungs'].airway_occluded"
    sim = hybrid.load(light_ribs(0.002, "forces.lungs.airway_occluded=0"))
    sim.step(5)
    assert sim.work.calls[CALL_HOLD] == 0
    sim.control.set(key, 1.0)
    sim.step(300)
    assert sim.work.calls[CALL_HOLD] != 0 and abs(sim.state.lung[L_HOLD]) > 0.0
    # closed by the program from the start, the run is the scheduled occlusion's, bit for bit
    scheduled, driven = hybrid.load(light_ribs(0.002)), hybrid.load(light_ribs(0.002, "forces.lungs.airway_occluded=0"))
    driven.control.set(key, 1.0)
    scheduled.step(50)
    driven.step(50)
    assert np.array_equal(scheduled.vert_pos, driven.vert_pos) and np.array_equal(
        scheduled.mj_data.qpos, driven.mj_data.qpos
    )


def test_a_staggered_hold_on_light_ribs_diverges_and_says_no_step_helps():
    scene = light_ribs(0.002, "rigid.integrator=RK4")
    gain = held_volumes_gain(compile_scene(scene))
    sim = hybrid.load(scene)
    with pytest.raises(SimulationDiverged) as caught:
        sim.step(400)
    assert gain.occluded > 1.0 and gain.open < 1.0  # the abdomen alone is held as before
    msg = str(caught.value)
    assert "will not help" in msg and f"{gain.occluded:.3g}" in msg and "try dt_s" not in msg
    assert caught.value.dt_suggested_s != caught.value.dt_suggested_s  # nan: no step suggested


def test_the_packaged_trunks_hold_their_volumes_far_inside_the_bound():
    lungs = held_volumes_gain(compile_scene(resolve_scene("breathing_lungs", overrides=["mesh.level=0"])))
    plain = held_volumes_gain(compile_scene(resolve_scene("breathing", overrides=["mesh.level=0"])))
    # about 0.14 each at level 0 (the ribs' 0.2 kg and their hinge damping against the dome's points)
    assert 0.0 < lungs.open < 0.5 and 0.0 < lungs.occluded < 0.5
    assert plain.occluded is None and plain.open == pytest.approx(lungs.open, rel=1e-12)  # the same trunk
    assert held_volumes_gain(compile_scene(resolve_scene("membrane_demo"))) is None  # no rigid part


def test_a_run_that_may_occlude_light_ribs_is_warned_and_inspect_reports_the_gain(capsys):
    from hybrid.cli import _warn_above_stable_step
    from hybrid.inspection import inspect_source

    scene = light_ribs(0.002, "rigid.integrator=RK4")
    assert may_occlude(scene) and not may_occlude(resolve_scene("breathing_lungs"))
    _warn_above_stable_step(compile_scene(scene))
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "smaller step will not cure" in err
    _warn_above_stable_step(compile_scene(resolve_scene("breathing_lungs", overrides=["mesh.level=0"])))
    assert capsys.readouterr().err == ""
    r = inspect_source("breathing_lungs", overrides=["mesh.level=0"])
    gain = held_volumes_gain(compile_scene(resolve_scene("breathing_lungs", overrides=["mesh.level=0"])))
    assert r["rigid"]["held_volumes_gain"] == {"open": gain.open, "occluded": gain.occluded}
    assert r["rigid"]["held_volumes"] == gain.line()
