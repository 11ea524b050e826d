"""`hybrid study rigid [SCENE] --out DIR`: the rigid part of a coupled run checked
against MuJoCo alone and against the paper's rigid algorithm.

1. Replay: the scene runs with its wrenches recorded (`Coupling.record_wrenches`); the
   recorded `xfrc_applied` (and the driven actuators' `ctrl`) of every step are replayed
   through MuJoCo alone (`hybrid.rigid.replay_states`, `mujoco.rollout`) from the run's
   initial state; `replay_max_abs_qpos` and `replay_max_abs_qvel` are the largest
   differences over every step (0 when the coupled loop drives MuJoCo as `mj_step` does).
2. Wrench: at every step, the membrane's loads on the bodies (the linked points' forces at
   their sites, the lungs' carried wall's at theirs, the sliding points' planes' reactions at
   the points) are summed in numpy into a force and a moment about each body's centre of mass,
   from the positions at the step's start, and compared with the recorded `xfrc_applied`:
   `wrench_rel_error` = max |difference| / max |xfrc_applied|.
3. The paper's rigid-region algorithm (section 3.5; `rigid_reference.run_paper`) against
   MuJoCo's RK4 at a fine step on a free body pushed by a body-fixed force, as h halves
   from 4 ms to 0.5 ms: `paper_algorithm_order`, the median observed order over position,
   angle, velocity and angular velocity.

Writes DIR/rigid.json and DIR/rigid.md.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..model import compile_scene
from ..outputs import write_text as _write_text
from ..resolve import resolve_scene
from ..simulation import Simulation
from . import rigid_reference as ref
from .stability.report import write_json

__all__ = ["run", "replay_check", "paper_order", "markdown"]

#: the paper algorithm's steps (s), halving, and MuJoCo's RK4 reference step
PAPER_STEPS_S = (4e-3, 2e-3, 1e-3, 5e-4)
REFERENCE_STEP_S = 1e-4


def replay_check(scene, nstep: int) -> dict:
    """Run `scene` for nstep steps, one at a time, recording; replay and compare (steps 1, 2)."""
    from ..rigid import replay_states

    sim = Simulation(compile_scene(scene))
    if sim.rigid is None:
        raise SceneError(f"study rigid: scene {scene.name!r} has no rigid part; expected a scene with [rigid]")
    coupling, d = sim.rigid, sim.mj_data
    coupling.record_wrenches = True
    system = coupling.system
    # every load the membrane puts on a body: the linked points' forces at their sites, the lungs'
    # wall's shares at theirs, and the sliding points' planes' reactions at the points themselves
    site_id, site_body = system.site_id, system.site_body
    wall_id, wall_body, wall_weight = system.wall_site_id, system.wall_site_body, system.wall_weight
    slide_vert, slide_body = system.slide_vert, system.slide_site_body
    qvel, ctrl, wrench_err, wrench_max = [], [], 0.0, 0.0
    for _k in range(nstep):
        site_pos, wall_pos, com = d.site_xpos[site_id].copy(), d.site_xpos[wall_id].copy(), d.xipos.copy()
        slide_pos = sim.state.vert_pos[slide_vert]
        sim.step(1)
        xfrc = coupling.wrench_history()[-1]
        mine = np.zeros_like(xfrc)
        for body, at, force in (
            (site_body, site_pos, coupling.link_forces()),
            (wall_body, wall_pos, wall_weight[:, None] * coupling.wall_forces()),
            (slide_body, slide_pos, -coupling.slide_forces()),
        ):
            np.add.at(mine[:, :3], body, force)
            np.add.at(mine[:, 3:], body, np.cross(at - com[body], force))
        bodies = np.unique(np.concatenate([site_body, wall_body, slide_body]))
        wrench_err = max(wrench_err, float(np.abs(mine[bodies] - xfrc[bodies]).max()))
        wrench_max = max(wrench_max, float(np.abs(xfrc[bodies]).max()))
        qvel.append(d.qvel.copy())
        ctrl.append(d.ctrl.copy())
    qpos_run = coupling.qpos_history()
    qpos_rep, qvel_rep = replay_states(
        coupling.mj_model,
        coupling.initial_state,
        coupling.wrench_history(),
        np.array(ctrl).reshape(nstep, -1),
        coupling.qfrc_history(),
    )
    return {
        "scene": scene.name,
        "steps": nstep,
        "dt_s": sim.model.dt_s,
        "replay_max_abs_qpos": float(np.abs(qpos_rep - qpos_run).max()) if qpos_run.size else 0.0,
        "replay_max_abs_qvel": float(np.abs(qvel_rep - np.array(qvel)).max()) if qvel_rep.size else 0.0,
        "wrench_rel_error": wrench_err / wrench_max if wrench_max > 0 else 0.0,
        "wrench_max_abs": wrench_max,
        "qpos_moved_max": float(np.abs(qpos_run - qpos_run[:1]).max()),
    }


def paper_order(duration_s: float = 1.0) -> dict:
    """Step 3: the paper's algorithm against MuJoCo's RK4 as h halves (as
    tests/studies/test_rigid_reference.py)."""
    body = ref.RigidBody(1.0, [0.01, 0.02, 0.03])
    state0 = ref.RigidState(vel=np.array([0.1, 0.0, 0.05]), omega=np.array([1.0, 2.0, 3.0]))
    point, force = np.array([0.1, 0.05, 0.0]), np.array([0.0, 2.0, 1.0])
    exact = ref.run_mujoco(body, state0, point, force, REFERENCE_STEP_S, duration_s, integrator="RK4")
    check = ref.run_mujoco(body, state0, point, force, 2 * REFERENCE_STEP_S, duration_s, integrator="RK4")
    errors = [ref.state_error(ref.run_paper(body, state0, point, force, h, duration_s), exact) for h in PAPER_STEPS_S]
    orders = {
        key: np.log2([e[key] / f[key] for e, f in zip(errors, errors[1:])]).tolist()
        for key in ("pos", "angle", "vel", "omega")
    }
    return {
        "steps_s": list(PAPER_STEPS_S),
        "errors": errors,
        "orders": orders,
        "reference_error": max(ref.state_error(exact, check).values()),
        "paper_algorithm_order": float(np.median(np.concatenate(list(orders.values())))),
    }


def run(out_dir, source=None, *, small: bool = False) -> dict:
    """The study (module docstring) of the scene `source` (default: breathing): 2000
    coupled steps (200 with small); writes DIR/rigid.json and DIR/rigid.md."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    scene = resolve_scene(source)
    res = replay_check(scene, 200 if small else 2000)
    paper = paper_order()
    res.update(paper_algorithm_order=paper["paper_algorithm_order"], paper=paper, runtime_s=time.perf_counter() - t0)
    write_json(out / "rigid.json", res)
    _write_text(out / "rigid.md", markdown(res))
    return res


def markdown(res: dict) -> str:
    p = res["paper"]
    rows = "\n".join(
        f"| {h:g} | " + " | ".join(f"{e[k]:.3e}" for k in ("pos", "angle", "vel", "omega")) + " |"
        for h, e in zip(p["steps_s"], p["errors"])
    )
    return f"""# The rigid part checked: scene {res["scene"]}

{res["steps"]} coupled steps of {res["dt_s"]:g} s (qpos moved by up to {res["qpos_moved_max"]:.3g}).

| check | value |
| --- | --- |
| replay through MuJoCo alone: max abs qpos difference | {res["replay_max_abs_qpos"]:.3e} |
| replay: max abs qvel difference | {res["replay_max_abs_qvel"]:.3e} |
| point forces against the applied wrench: max relative difference | {res["wrench_rel_error"]:.3e} |
| the paper's rigid algorithm against MuJoCo RK4: observed order (median) | {res["paper_algorithm_order"]:.3f} |

The paper's algorithm (section 3.5, explicit Euler) on a free body under a body-fixed
force, 1 s, against MuJoCo's RK4 at {REFERENCE_STEP_S:g} s (converged to {p["reference_error"]:.1e}):

| h (s) | position (m) | angle (rad) | velocity (m/s) | angular velocity (rad/s) |
| --- | --- | --- | --- | --- |
{rows}
"""
