"""What a scene changes in its rigid model (`Rigid`'s control keys), applied to the
loaded `mujoco.MjSpec` before anything else is added; the model's files are only read.

- `keyframe`: the run starts from this keyframe (qpos, qvel, act, ctrl); the membrane's
  attachment sites are placed against the bodies where they start;
- `fix` / `fix_root`: the named bodies' joints (every free-floating root's free joint)
  removed, each body then fixed to its parent at its start pose (exact);
- `weld`: the named bodies welded to the world at their start pose (a MuJoCo weld
  equality, as stiff as the step allows: solref time constant 2 dt);
- `hold`: joints (names or glob patterns) held at their start position by springs of
  `hold_stiffness_nm_per_rad` and `hold_damping_nms_per_rad` (N/m, N s/m for a slide
  joint), which replace the joint's own stiffness, damping and spring reference;
- `lock`: hinge or slide joints locked at their start position (joint equalities);
- `ctrl`: actuators (names or patterns) driven by schedules, set before every step;
- `integrator`: MuJoCo's integrator, the MJCF's own unless set.

Every unknown name is refused in one line that lists the closest names of its kind.
"""

from __future__ import annotations

import difflib
import fnmatch
from dataclasses import dataclass, field

import mujoco
import numpy as np

from hybrid import checks
from hybrid import schedule as S
from hybrid.errors import RigidError, SceneError
from hybrid.scene import MUJOCO_INTEGRATORS, Rigid

from .mjcf import compile_spec

__all__ = ["Controls", "apply_controls", "close_names", "start_data"]

_FREE = mujoco.mjtJoint.mjJNT_FREE
_JOINT_KINDS = {
    int(mujoco.mjtJoint.mjJNT_FREE): "free",
    int(mujoco.mjtJoint.mjJNT_BALL): "ball",
    int(mujoco.mjtJoint.mjJNT_SLIDE): "slide",
    int(mujoco.mjtJoint.mjJNT_HINGE): "hinge",
}
# weld and lock constraints as hard as MuJoCo's soft constraints go (impedance 0.99-0.999)
_SOLIMP = [0.99, 0.999, 0.001, 0.5, 2.0]
_NQ = {"free": 7, "ball": 4, "slide": 1, "hinge": 1}
_NV = {"free": 6, "ball": 3, "slide": 1, "hinge": 1}


@dataclass
class Controls:
    """What `apply_controls` did. key_id: the start keyframe's index (-1: qpos0);
    spring_qpos {joint name: start qpos (m or rad; 4 values for a ball joint)} of the held
    joints, for `qpos_spring` of the compiled model; ctrl_actuators (nc,) names and
    ctrl_schedules (nc,) the schedules that drive them; settings: what the summary
    records (JSON values); load_joints: the joints `hybrid.loads` takes moments about."""

    key_id: int = -1
    spring_qpos: dict = field(default_factory=dict)
    ctrl_actuators: tuple = ()
    ctrl_schedules: tuple = ()
    settings: dict = field(default_factory=dict)
    load_joints: tuple = ()

    def finish(self, model: mujoco.MjModel) -> None:
        """Set the held joints' spring positions in the compiled `model` (a ball joint's
        spring reference cannot be set in the spec)."""
        for name, q in self.spring_qpos.items():
            adr = model.jnt_qposadr[model.joint(name).id]
            model.qpos_spring[adr : adr + len(q)] = q


def close_names(name: str, names, kind: str) -> str:
    """ "; close KIND names: a, b" (difflib), or the first names of that kind."""
    unnamed = sum(1 for n in names if not n)
    names = [n for n in names if n]
    near = difflib.get_close_matches(str(name), names, n=5, cutoff=0.5)
    if near:
        return f"close {kind} names: {', '.join(near)}"
    if not names:
        return f"the model's {unnamed} {kind}s have no names" if unnamed else f"the model has no {kind}s"
    return f"{kind} names: {', '.join(names[:12])}{' ...' if len(names) > 12 else ''}"


def _names(model, kind: str, count: int) -> list[str]:
    return [getattr(model, kind)(i).name for i in range(count)]


def _name_list(what: str, value) -> tuple:
    if isinstance(value, str) or not isinstance(value, (list, tuple)):
        raise SceneError(f"{what}: expected a list of names, received {checks.show(value)}")
    for k, v in enumerate(value):
        if not isinstance(v, str) or not v:
            raise SceneError(f"{what}[{k}]: expected a non-empty name, received {checks.show(v)}")
    return tuple(value)


def _match(what: str, patterns, names: list[str], kind: str, label: str) -> list[str]:
    """The names matching any pattern (glob), in model order; a pattern matching none refused."""
    chosen = []
    for k, pat in enumerate(patterns):
        hit = [n for n in names if fnmatch.fnmatchcase(n, pat)]
        if not hit:
            raise RigidError(f"{what}[{k}]: no {kind} named {pat!r} in {label}; {close_names(pat, names, kind)}")
        chosen += [n for n in hit if n not in chosen]
    return chosen


def start_data(model: mujoco.MjModel, key_id: int) -> mujoco.MjData:
    """An MjData at the start pose (the keyframe key_id, or qpos0), kinematics computed."""
    data = mujoco.MjData(model)
    if key_id >= 0:
        mujoco.mj_resetDataKeyframe(model, data, key_id)
    mujoco.mj_kinematics(model, data)
    return data


def _quat_inv_mul(qa, qb) -> np.ndarray:
    """qa^-1 qb (unit quaternions, w first)."""
    inv, out = np.empty(4), np.empty(4)
    mujoco.mju_negQuat(inv, np.asarray(qa, float))
    mujoco.mju_mulQuat(out, inv, np.asarray(qb, float))
    return out


def _rel_pose(data, parent: int, body: int) -> tuple[np.ndarray, np.ndarray]:
    """The pose of `body` in `parent`'s frame (pos m, quat)."""
    rot = data.xmat[parent].reshape(3, 3)
    return rot.T @ (data.xpos[body] - data.xpos[parent]), _quat_inv_mul(data.xquat[parent], data.xquat[body])


def _rib_muscles(ribs) -> list:
    """The actuators `rigid.ribs` will add (`hybrid.rigid.ribs`: a pair's muscles, when its
    muscle_gear_n_m > 0), which `rigid.ctrl` may drive."""
    pairs = getattr(ribs, "pairs", ()) or ()
    return [
        f"{p.name}_{side}_muscle"
        for p in pairs
        if isinstance(getattr(p, "muscle_gear_n_m", None), (int, float)) and p.muscle_gear_n_m > 0
        for side in ("left", "right")
    ]


def apply_controls(spec: mujoco.MjSpec, rig: Rigid, label: str, timestep_s: float | None) -> Controls:
    """Apply `rig`'s control keys to `spec` in place (module docstring); returns what
    was done. timestep_s: the scene's step (None: the MJCF's own), for the weld and lock
    constraints' time constant. Raises SceneError (a malformed value) or RigidError (a
    name the model lacks, with the close names), one line each."""
    out = Controls()
    model0 = compile_spec(spec, label)
    dt = float(timestep_s) if timestep_s is not None else float(model0.opt.timestep)
    keys = _names(model0, "key", model0.nkey)
    bodies = _names(model0, "body", model0.nbody)
    joints = _names(model0, "joint", model0.njnt)
    kinds = {n: _JOINT_KINDS[int(model0.jnt_type[j])] for j, n in enumerate(joints)}

    if rig.keyframe is not None:
        key = checks.text("rigid.keyframe", rig.keyframe)
        if key not in keys:
            raise RigidError(
                f"rigid.keyframe: no keyframe named {key!r} in {label}; {close_names(key, keys, 'keyframe')}"
            )
        out.key_id = keys.index(key)
    data0 = start_data(model0, out.key_id)
    qstart = data0.qpos.copy()

    # bodies fixed to their parents: joints removed, the body put at its start pose
    fixed = [_body(f"rigid.fix[{k}]", n, bodies, label) for k, n in enumerate(_name_list("rigid.fix", rig.fix))]
    if checks.boolean("rigid.fix_root", rig.fix_root):
        roots = [
            bodies[b]
            for b in range(1, model0.nbody)
            if model0.body_parentid[b] == 0
            and model0.body_jntnum[b]
            and model0.jnt_type[model0.body_jntadr[b]] == _FREE
        ]
        if not roots:
            raise RigidError(
                f"rigid.fix_root: {label} has no free-floating root body (a body on the world "
                f"with a free joint); bodies on the world: "
                f"{[bodies[b] for b in range(1, model0.nbody) if model0.body_parentid[b] == 0]}"
            )
        fixed += [b for b in roots if b not in fixed]
    drop_q, drop_v = [], []
    for name in fixed:
        b = model0.body(name).id
        if model0.body_jntnum[b] == 0:
            raise RigidError(
                f"rigid.fix: body {name!r} has no joint: it is fixed to its parent "
                f"{bodies[model0.body_parentid[b]]!r} already"
            )
        for j in range(model0.body_jntadr[b], model0.body_jntadr[b] + model0.body_jntnum[b]):
            _refuse_driven(model0, j, name)
            kind = _JOINT_KINDS[int(model0.jnt_type[j])]
            drop_q += range(model0.jnt_qposadr[j], model0.jnt_qposadr[j] + _NQ[kind])
            drop_v += range(model0.jnt_dofadr[j], model0.jnt_dofadr[j] + _NV[kind])
        sb = spec.body(name)
        for jnt in list(sb.joints):
            spec.delete(jnt)
        pos, quat = _rel_pose(data0, int(model0.body_parentid[b]), b)
        if sb.frame is not None:
            raise RigidError(
                f"rigid.fix: body {name!r} is placed through an MJCF <frame>; fix its parent or weld it instead"
            )
        sb.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        sb.pos, sb.quat = pos.tolist(), quat.tolist()
    if drop_q:
        keep_q = np.setdiff1d(np.arange(model0.nq), drop_q)
        keep_v = np.setdiff1d(np.arange(model0.nv), drop_v)
        for key in spec.keys:
            if len(key.qpos) == model0.nq:
                key.qpos = np.asarray(key.qpos)[keep_q].tolist()
            if len(key.qvel) == model0.nv:
                key.qvel = np.asarray(key.qvel)[keep_v].tolist()
    gone = {n for b in fixed for n in joints if model0.jnt_bodyid[model0.joint(n).id] == model0.body(b).id}

    # bodies welded to the world where they start
    welded = [_body(f"rigid.weld[{k}]", n, bodies, label) for k, n in enumerate(_name_list("rigid.weld", rig.weld))]
    for name in welded:
        b = model0.body(name).id
        if b == 0:
            raise RigidError("rigid.weld: 'world' cannot be welded to itself; expected a body of the model")
        rot = data0.xmat[b].reshape(3, 3)
        eq = spec.add_equality(type=mujoco.mjtEq.mjEQ_WELD, name1=name, name2="world", objtype=mujoco.mjtObj.mjOBJ_BODY)
        eq.data[0:11] = [0.0, 0.0, 0.0, *(rot.T @ -data0.xpos[b]), *_quat_inv_mul(data0.xquat[b], [1, 0, 0, 0]), 1.0]
        eq.solref, eq.solimp = [2.0 * dt, 1.0], _SOLIMP

    # joints held by springs or locked, at their start position
    free_names = [n for n in joints if n not in gone]
    held = _joints("rigid.hold", rig.hold, free_names, kinds, label, ("free",))
    locked = _joints("rigid.lock", rig.lock, free_names, kinds, label, ("free", "ball"))
    both = sorted(set(held) & set(locked))
    if both:
        raise SceneError(f"rigid.hold and rigid.lock: joints {both} are in both; expected each held or locked")
    k_hold = checks.positive(
        "rigid.hold_stiffness_nm_per_rad", rig.hold_stiffness_nm_per_rad, checks.MAX_STIFFNESS_N_PER_M
    )
    c_hold = checks.number(
        "rigid.hold_damping_nms_per_rad",
        rig.hold_damping_nms_per_rad,
        lo=0,
        lo_open=False,
        hi=checks.MAX_STIFFNESS_N_PER_M,
        hi_open=False,
    )
    for name in held:
        j = model0.joint(name).id
        adr = model0.jnt_qposadr[j]
        q = qstart[adr : adr + _NQ[kinds[name]]]
        sj = spec.joint(name)
        _set_linear(sj, "stiffness", k_hold)
        _set_linear(sj, "damping", c_hold)
        out.spring_qpos[name] = q.tolist()  # the spring reference, set in the compiled model (radians)
    for name in locked:
        j = model0.joint(name).id
        adr = model0.jnt_qposadr[j]
        eq = spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=name, objtype=mujoco.mjtObj.mjOBJ_JOINT)
        eq.data[0:5] = [float(qstart[adr] - model0.qpos0[adr]), 0.0, 0.0, 0.0, 0.0]
        eq.solref, eq.solimp = [2.0 * dt, 1.0], _SOLIMP

    # actuators driven by schedules: the model's, and the rib muscles `rigid.ribs` adds after this
    actuators = _names(model0, "actuator", model0.nu) + _rib_muscles(rig.ribs)
    ctrl = rig.ctrl
    if not isinstance(ctrl, dict):
        raise SceneError(
            f"rigid.ctrl: expected a table {{actuator name or pattern = schedule}}, received {checks.show(ctrl)}"
        )
    owner: dict[str, str] = {}
    for pat, sched in ctrl.items():
        what = f"rigid.ctrl.{pat}"
        hit = _match("rigid.ctrl", [pat], actuators, "actuator", label)
        sched = S.as_schedule(sched, name=what, ncomp=1)
        if isinstance(sched, S.Function):
            raise SceneError(
                f"{what}: a Python function cannot drive an actuator in the compiled step; "
                f"expected a number, a breathing waveform or a table"
            )
        for a in hit:
            if a in owner:
                raise SceneError(
                    f"{what}: actuator {a!r} is driven by rigid.ctrl.{owner[a]} already; expected "
                    f"each actuator driven once"
                )
            owner[a] = pat
            out.ctrl_actuators += (a,)
            out.ctrl_schedules += (sched,)

    # joints the loads' moments are taken about (hybrid.loads): joints of the compiled model
    for k, name in enumerate(_name_list("rigid.load_joints", rig.load_joints)):
        if name not in free_names:
            why = " (removed: its body is fixed)" if name in gone else ""
            raise RigidError(
                f"rigid.load_joints[{k}]: no joint named {name!r} in {label}{why}; "
                f"{close_names(name, free_names, 'joint')}"
            )
    out.load_joints = tuple(rig.load_joints)

    if rig.integrator is not None:
        name = checks.text("rigid.integrator", rig.integrator, MUJOCO_INTEGRATORS)
        spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{name.upper()}")
    integ = {int(getattr(mujoco.mjtIntegrator, f"mjINT_{n.upper()}")): n for n in MUJOCO_INTEGRATORS}
    out.settings = {
        "mjcf_timestep_s": float(model0.opt.timestep),
        "integrator": integ.get(int(spec.option.integrator), str(spec.option.integrator)),
        "integrator_from": "mjcf" if rig.integrator is None else "scene",
        "keyframe": rig.keyframe,
        "fixed": fixed,
        "welded": welded,
        "held": held,
        "locked": locked,
        "driven": list(out.ctrl_actuators),
    }
    if fixed:
        _check_fixed_where_they_start(spec, label, out.key_id, fixed, data0, model0)
    return out


def _refuse_driven(model, j: int, body: str) -> None:
    """A joint an actuator drives cannot be removed: refused, naming both."""
    joint_trn = (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))
    for a in range(model.nu):
        if int(model.actuator_trntype[a]) in joint_trn and int(model.actuator_trnid[a, 0]) == j:
            raise RigidError(
                f"rigid.fix: body {body!r}: its joint {model.joint(j).name!r} is driven by actuator "
                f"{model.actuator(a).name!r}; expected a body whose joints no actuator drives "
                f"(lock or hold the joint instead)"
            )


def _set_linear(joint, attr: str, value: float) -> None:
    """A joint's linear coefficient (MuJoCo 4 keeps [linear, nonlinear terms]); the others 0."""
    cur = np.atleast_1d(np.asarray(getattr(joint, attr), float))
    new = np.zeros_like(cur)
    new[0] = value
    setattr(joint, attr, float(new[0]) if np.ndim(getattr(joint, attr)) == 0 else new.tolist())


def _body(what: str, name: str, bodies: list[str], label: str) -> str:
    if name not in bodies:
        raise RigidError(f"{what}: no body named {name!r} in {label}; {close_names(name, bodies, 'body')}")
    return name


def _joints(what: str, patterns, names: list[str], kinds: dict, label: str, refused: tuple) -> list[str]:
    """The joints named (or matched) by `patterns`; a pattern skips joints of the refused
    kinds, an exact name of one is refused."""
    patterns = _name_list(what, patterns)
    for k, pat in enumerate(patterns):
        if pat in kinds and kinds[pat] in refused:
            hint = (
                "fix its body (rigid.fix, rigid.fix_root) or weld it"
                if kinds[pat] == "free"
                else "hold it, or fix its body"
            )
            raise RigidError(
                f"{what}[{k}]: joint {pat!r} is a {kinds[pat]} joint; expected a "
                f"{' or '.join(k2 for k2 in ('hinge', 'slide', 'ball') if k2 not in refused)} "
                f"joint; {hint}"
            )
    usable = [n for n in names if kinds[n] not in refused]
    for k, pat in enumerate(patterns):
        if pat in kinds and pat not in names:
            raise RigidError(
                f"{what}[{k}]: joint {pat!r} belongs to a fixed body (rigid.fix); expected a joint that is kept"
            )
    return _match(what, patterns, usable, "joint", label)


def _check_fixed_where_they_start(spec, label, key_id, fixed, data0, model0) -> None:
    """The fixed bodies stand where they started (catches an MJCF whose body frames
    this module does not place, rather than moving a body silently)."""
    model1 = compile_spec(spec, f"{label} with rigid.fix")
    data1 = start_data(model1, key_id if key_id < model1.nkey else -1)
    for name in fixed:
        b0, b1 = model0.body(name).id, model1.body(name).id
        err = np.abs(data1.xpos[b1] - data0.xpos[b0]).max()
        if err > 1e-9:
            raise RigidError(
                f"rigid.fix: body {name!r} would move by {err:.3g} m when fixed in {label}; "
                f"expected it to stay where it starts (weld it instead)"
            )
