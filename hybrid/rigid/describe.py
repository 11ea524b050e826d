"""What a compiled MuJoCo model holds, as plain data (`hybrid inspect`): its bodies
with their world positions at `qpos0`, joints, actuators and keyframes, its timestep
and integrator. JSON values only (lists, floats, strings)."""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["describe_model", "describe_spec", "hinge_qpos"]

_JOINT = {
    int(mujoco.mjtJoint.mjJNT_FREE): "free",
    int(mujoco.mjtJoint.mjJNT_BALL): "ball",
    int(mujoco.mjtJoint.mjJNT_SLIDE): "slide",
    int(mujoco.mjtJoint.mjJNT_HINGE): "hinge",
}
_INTEGRATOR = {
    int(mujoco.mjtIntegrator.mjINT_EULER): "Euler",
    int(mujoco.mjtIntegrator.mjINT_RK4): "RK4",
    int(mujoco.mjtIntegrator.mjINT_IMPLICIT): "implicit",
    int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST): "implicitfast",
}


def hinge_qpos(model: mujoco.MjModel, chosen) -> np.ndarray:
    """The qpos addresses of the hinge joints of `model`'s bodies whose name `chosen(name)` takes."""
    hinge = int(mujoco.mjtJoint.mjJNT_HINGE)
    return np.array(
        [
            model.jnt_qposadr[j]
            for j in range(model.njnt)
            if int(model.jnt_type[j]) == hinge and chosen(model.body(int(model.jnt_bodyid[j])).name)
        ],
        dtype=np.int64,
    )


def _floats(a) -> list:
    return [float(x) for x in np.ravel(a)]


def _target(model: mujoco.MjModel, a: int) -> str:
    """The actuator's transmission target, "joint:NAME", "tendon:NAME", ..."""
    trn = mujoco.mjtTrn(int(model.actuator_trntype[a])).name.removeprefix("mjTRN_").lower()
    obj = {
        "joint": mujoco.mjtObj.mjOBJ_JOINT,
        "jointinparent": mujoco.mjtObj.mjOBJ_JOINT,
        "tendon": mujoco.mjtObj.mjOBJ_TENDON,
        "site": mujoco.mjtObj.mjOBJ_SITE,
        "body": mujoco.mjtObj.mjOBJ_BODY,
        "slidercrank": mujoco.mjtObj.mjOBJ_SITE,
    }.get(trn)
    tid = int(model.actuator_trnid[a, 0])
    name = mujoco.mj_id2name(model, obj, tid) if obj is not None and tid >= 0 else None
    return f"{trn}:{name}" if name else trn


def describe_model(model: mujoco.MjModel) -> dict:
    """{"timestep_s", "integrator", "gravity_m_s2", "nq", "nv", "nu", "bodies", "joints",
    "actuators", "keyframes"} of `model`; each body with its parent, mass (kg) and world
    position at qpos0 (m), each joint with its kind, body, qpos0 and range, each actuator
    with its target and control range, each keyframe with its qpos."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    bodies = [
        {
            "name": model.body(b).name,
            "parent": model.body(int(model.body_parentid[b])).name,
            "mass_kg": float(model.body_mass[b]),
            "pos_m": _floats(data.xpos[b]),
        }
        for b in range(model.nbody)
    ]
    joints = []
    for j in range(model.njnt):
        kind = _JOINT[int(model.jnt_type[j])]
        adr = int(model.jnt_qposadr[j])
        size = {"free": 7, "ball": 4}.get(kind, 1)
        joints.append(
            {
                "name": model.joint(j).name,
                "type": kind,
                "body": model.body(int(model.jnt_bodyid[j])).name,
                "qpos0": _floats(model.qpos0[adr : adr + size]),
                "range": _floats(model.jnt_range[j]) if model.jnt_limited[j] else None,
            }
        )
    actuators = [
        {
            "name": model.actuator(a).name,
            "target": _target(model, a),
            "ctrlrange": _floats(model.actuator_ctrlrange[a]) if model.actuator_ctrllimited[a] else None,
        }
        for a in range(model.nu)
    ]
    keyframes = [{"name": model.key(k).name, "qpos": _floats(model.key_qpos[k])} for k in range(model.nkey)]
    return {
        "timestep_s": float(model.opt.timestep),
        "integrator": _INTEGRATOR.get(int(model.opt.integrator), str(int(model.opt.integrator))),
        "gravity_m_s2": _floats(model.opt.gravity),
        "nq": int(model.nq),
        "nv": int(model.nv),
        "nu": int(model.nu),
        "bodies": bodies,
        "joints": joints,
        "actuators": actuators,
        "keyframes": keyframes,
    }


def describe_spec(source: str) -> dict:
    """`describe_model` of an MJCF file (or "trunk"), compiled as it is."""
    from .mjcf import BUILTIN_MJCF, compile_spec, load_spec

    path = BUILTIN_MJCF.get(str(source), source)
    return describe_model(compile_spec(load_spec(path), str(source)))
