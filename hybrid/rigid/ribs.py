"""Articulated ribs added to a loaded model through `mujoco.MjSpec` (`Rigid.ribs`).

No MJCF model on the package registries has articulated ribs (myotorso's rib cage is
one rigid body). `add_ribs` adds pairs of rib bodies to a named thoracic body: each rib
hinged at its costovertebral joint, its axis in the transverse plane at an angle to the
mid-sagittal plane (90 degrees: pump handle, 0: bucket handle; Wilson et al. 1987 measure
about 35 degrees at the upper ribs), with a hinge spring (stiffness, damping, rest angle),
drawn as capsules along an arc; the two anterior ends of a pair joined by a spatial
tendon, a spring at its rest length (the costal cartilage and sternum). A spring rather
than an equality: two hinges whose axes differ, joined rigidly at their ends, would lock.

Positions are given for the left rib in the world where the model starts (its keyframe,
or qpos0), as `hybrid inspect` lists bodies; the right rib is its mirror image in the
mid-sagittal plane through the thoracic body's origin. The spec is changed in place; the
model's files are only read. Every value and name is checked, one line each.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import mujoco
import numpy as np

from hybrid import checks
from hybrid.errors import RigidError, SceneError
from hybrid.rigidfile import reference_angle
from hybrid.scene import RibPair, Ribs
from hybrid.terms.base import check_value

from .controls import _set_linear, close_names, start_data
from .mjcf import compile_spec

__all__ = ["RibsAdded", "add_ribs", "rib_arc"]

#: capsules a rib is drawn with
SEGMENTS = 6
#: geom group of the ribs' capsules (drawn by `hybrid render` and the viewer: groups 0-2)
_GROUP = 1
_RGBA = [0.92, 0.88, 0.78, 1.0]
#: anterior and cranial must be perpendicular within this (cosine of their angle)
_PERPENDICULAR_TOL = 1e-3
_SIDES = ("left", "right")


@dataclass
class RibsAdded:
    """What `add_ribs` added: the thoracic body; the model's unit directions (anterior,
    cranial, left) in the world; per pair its bodies, hinge joints, front sites and tendon
    (names); settings: what the summary records (JSON values)."""

    body: str
    anterior: np.ndarray
    cranial: np.ndarray
    left: np.ndarray
    bodies: list = field(default_factory=list)
    joints: list = field(default_factory=list)
    fronts: list = field(default_factory=list)
    tendons: list = field(default_factory=list)

    def settings(self) -> dict:
        return {
            "body": self.body,
            "rib_bodies": list(self.bodies),
            "rib_joints": list(self.joints),
            "sternum_tendons": list(self.tendons),
        }


def _unit(where: str, v) -> np.ndarray:
    x = np.asarray(check_value(where, "vec3", v), float)
    n = float(np.linalg.norm(x))
    if n == 0.0:
        raise SceneError(f"{where}: expected a non-zero direction, received {checks.show(v)}")
    return x / n


def _value(where: str, obj, name: str):
    """Field `name` of dataclass obj checked by its kind (hybrid.terms.base.param)."""
    f = {f.name: f for f in fields(obj)}[name]
    return check_value(f"{where}.{name}", f.metadata["kind"], getattr(obj, name), f.metadata)


def rib_arc(
    head: np.ndarray,
    front: np.ndarray,
    outward: np.ndarray,
    lateral_head: float,
    lateral_front: float,
    half_width_m: float,
    n: int = SEGMENTS,
) -> np.ndarray:
    """(n + 1, 3) m: points along a rib from its head to its anterior end, bowed outward
    (unit `outward`, away from the midline) so that its middle lies half_width_m from the
    midline: the chord plus (half_width_m - mean lateral offset) sin(pi t) outward."""
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    bulge = half_width_m - 0.5 * (lateral_head + lateral_front)
    return head + t * (front - head) + bulge * np.sin(np.pi * t) * outward


def _names_taken(spec: mujoco.MjSpec, names: dict) -> str | None:
    """The first of names {name: kind} the spec has already (any element kind), or None."""
    lookup = {
        "body": spec.body,
        "joint": spec.joint,
        "site": spec.site,
        "tendon": spec.tendon,
        "actuator": spec.actuator,
    }
    for name, kind in names.items():
        if lookup[kind](name) is not None:
            return f"{kind} {name!r}"
    return None


def _inertia(points: np.ndarray, mass: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass and inertia tensor (about it) of solid uniform rods of `radius` between
    consecutive points, of total mass `mass` spread by length. (Thin rods in a plane have a
    degenerate tensor, its largest moment the sum of the other two: MuJoCo's check A + B >= C
    then fails or passes by rounding, and refused a 0.5 kg rib of the breathing trunk's upper
    pair. A rod's own thickness, m r^2 / 4 (1 + u u^T), makes it strictly physical.)"""
    seg = np.diff(points, axis=0)
    length = np.linalg.norm(seg, axis=1)
    m = mass * length / length.sum()
    mid = 0.5 * (points[1:] + points[:-1])
    com = (m[:, None] * mid).sum(axis=0) / mass
    tensor = np.zeros((3, 3))
    eye = np.eye(3)
    for mk, c, s, ell in zip(m, mid, seg, length):
        r = c - com
        u = s / ell
        tensor += mk * (r @ r * eye - np.outer(r, r)) + mk * ell**2 / 12.0 * (eye - np.outer(u, u))
        tensor += mk * radius**2 / 4.0 * (eye + np.outer(u, u))
    return com, tensor


def add_ribs(spec: mujoco.MjSpec, ribs: Ribs, label: str, key_id: int = -1) -> RibsAdded:
    """Add `ribs`'s pairs to `spec` in place (module docstring). label: the model's name
    for messages; key_id: the keyframe the model starts from (-1: qpos0), where the
    positions are given. Raises SceneError (a malformed value) or RigidError (a body the
    model lacks, with the close names; a name already taken), one line each."""
    if not isinstance(ribs, Ribs):
        raise SceneError(f"rigid.ribs: expected a hybrid.scene.Ribs, received {type(ribs).__name__}")
    model0 = compile_spec(spec, label)
    bodies = [model0.body(i).name for i in range(model0.nbody)]
    body = checks.text("rigid.ribs.body", ribs.body)
    if body not in bodies or body == "world" or model0.body(body).id == 0:
        raise RigidError(
            f"rigid.ribs.body: no body named {body!r} in {label} (the thoracic body the ribs "
            f"hang on); {close_names(body, bodies[1:], 'body')}"
        )
    anterior = _unit("rigid.ribs.anterior", ribs.anterior)
    cranial = _unit("rigid.ribs.cranial", ribs.cranial)
    if abs(anterior @ cranial) > _PERPENDICULAR_TOL:
        raise SceneError(
            f"rigid.ribs.cranial: expected a direction perpendicular to rigid.ribs.anterior "
            f"{list(ribs.anterior)}, received {list(ribs.cranial)} (at "
            f"{np.degrees(np.arccos(np.clip(anterior @ cranial, -1, 1))):.3g} degrees)"
        )
    cranial = cranial - (anterior @ cranial) * anterior
    cranial /= np.linalg.norm(cranial)
    left = np.cross(cranial, anterior)
    radius = _value("rigid.ribs", ribs, "radius_m")
    k_sternum = _value("rigid.ribs", ribs, "sternum_stiffness_n_per_m")
    c_sternum = _value("rigid.ribs", ribs, "sternum_damping_n_s_per_m")
    pairs = ribs.pairs
    if not isinstance(pairs, (tuple, list)) or not pairs:
        raise SceneError(
            f"rigid.ribs.pairs: expected at least one rib pair ([[rigid.ribs.pairs]]), received {checks.show(pairs)}"
        )

    data0 = start_data(model0, key_id)
    bid = model0.body(body).id
    origin, rot = data0.xpos[bid].copy(), data0.xmat[bid].reshape(3, 3).copy()
    parent = spec.body(body)
    gravity = np.asarray(model0.opt.gravity, float)
    out = RibsAdded(body=body, anterior=anterior, cranial=cranial, left=left)
    seen: set = set()
    for k, pair in enumerate(pairs):
        where = f"rigid.ribs.pairs[{k}]"
        if not isinstance(pair, RibPair):
            raise SceneError(f"{where}: expected a hybrid.scene.RibPair, received {type(pair).__name__}")
        name = _value(where, pair, "name")
        if name in seen:
            raise SceneError(f"{where}.name: {name!r} names two rib pairs; expected each pair named once")
        seen.add(name)
        head = np.asarray(_value(where, pair, "head_m"))
        front = np.asarray(_value(where, pair, "front_m"))
        width = _value(where, pair, "half_width_m")
        alpha = np.radians(_value(where, pair, "axis_angle_deg"))
        stiff = _value(where, pair, "stiffness_n_m_per_rad")
        damp = _value(where, pair, "damping_n_m_s_per_rad")
        ref = np.radians(reference_angle(f"{where}.reference_angle_deg", pair.reference_angle_deg))
        mass = _value(where, pair, "mass_kg")
        gear = _value(where, pair, "muscle_gear_n_m")
        lat_head, lat_front = float((head - origin) @ left), float((front - origin) @ left)
        for key, lat in (("head_m", lat_head), ("front_m", lat_front)):
            if lat < radius:
                raise SceneError(
                    f"{where}.{key}: expected the left rib's point, at least radius_m ({radius:g} m) "
                    f"left of the mid-sagittal plane (left = cranial x anterior = "
                    f"{np.round(left, 6).tolist()}, the plane through {body!r}'s origin "
                    f"{np.round(origin, 6).tolist()}), received {lat:.4g} m from it"
                )
        if width <= max(lat_head, lat_front):
            raise SceneError(
                f"{where}.half_width_m: expected more than the head's and the anterior end's distance "
                f"from the mid-sagittal plane ({max(lat_head, lat_front):.4g} m), received {width:g}"
            )
        if np.linalg.norm(front - head) < 4.0 * radius:
            raise SceneError(
                f"{where}.front_m: expected the anterior end at least 4 radius_m from the head "
                f"{head.tolist()}, received {front.tolist()}"
            )
        names = {f"{name}_{s}": "body" for s in _SIDES}
        names.update({f"{name}_{s}_hinge": "joint" for s in _SIDES})
        names.update({f"{name}_{s}_front": "site" for s in _SIDES})
        names[f"{name}_sternum"] = "tendon"
        if gear > 0:
            names.update({f"{name}_{s}_muscle": "actuator" for s in _SIDES})
        taken = _names_taken(spec, names)
        if taken:
            raise RigidError(
                f"{where}.name: {label} has a {taken} already; expected a rib pair name whose bodies, "
                f"joints, sites and tendon are new"
            )
        for side, sign in (("left", 1.0), ("right", -1.0)):
            if sign > 0:
                h, f = head, front
            else:  # the mirror image in the mid-sagittal plane
                h = head - 2.0 * lat_head * left
                f = front - 2.0 * lat_front * left
            arc = rib_arc(h, f, sign * left, lat_head, lat_front, width)
            local = (arc - h) @ rot  # in the thoracic body's axes, from the head
            # hinge axis: a positive angle lifts the rib (pump: about -left; bucket: about +-anterior)
            axis = -np.sin(alpha) * left + sign * np.cos(alpha) * anterior
            rib = parent.add_body(name=f"{name}_{side}", pos=(rot.T @ (h - origin)).tolist(), quat=[1, 0, 0, 0])
            com, tensor = _inertia(local, mass, radius)
            rib.explicitinertial = True
            rib.mass, rib.ipos = float(mass), com.tolist()
            rib.fullinertia = [tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2], tensor[1, 2]]
            joint = rib.add_joint(
                name=f"{name}_{side}_hinge",
                type=mujoco.mjtJoint.mjJNT_HINGE,
                axis=(rot.T @ axis).tolist(),
                pos=[0.0, 0.0, 0.0],
            )
            # not the model's joint defaults (limits, armature, friction): a free hinge with its spring
            joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
            joint.armature, joint.frictionloss = 0.0, 0.0
            _set_linear(joint, "stiffness", stiff)
            _set_linear(joint, "damping", damp)
            # the spring holds the rib's own weight where it is drawn (MuJoCo's gravity), then ref beyond
            weight_torque = float(axis @ np.cross(rot @ com, mass * gravity))
            joint.springref = float(ref - weight_torque / stiff)
            seg_len = np.linalg.norm(np.diff(local, axis=0), axis=1)
            for j in range(SEGMENTS):
                rib.add_geom(
                    name=f"{name}_{side}_{j}",
                    type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                    fromto=[*local[j], *local[j + 1]],
                    size=[radius, 0.0, 0.0],
                    mass=float(mass * seg_len[j] / seg_len.sum()),
                    contype=0,
                    conaffinity=0,
                    group=_GROUP,
                    rgba=_RGBA,
                )
            rib.add_site(
                name=f"{name}_{side}_front", pos=local[-1].tolist(), size=[radius, radius, radius], group=_GROUP
            )
            if gear > 0:  # the rib cage's inspiratory muscles: torque = activation x gear, lifting the rib
                act = spec.add_actuator(
                    name=f"{name}_{side}_muscle",
                    target=f"{name}_{side}_hinge",
                    trntype=mujoco.mjtTrn.mjTRN_JOINT,
                    gear=[gear, 0.0, 0.0, 0.0, 0.0, 0.0],
                )
                act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
                act.ctrlrange = [0.0, 1.0]
            out.bodies.append(f"{name}_{side}")
            out.joints.append(f"{name}_{side}_hinge")
            out.fronts.append(f"{name}_{side}_front")
        tendon = spec.add_tendon(name=f"{name}_sternum", rgba=[0.6, 0.6, 0.9, 1.0])
        tendon.limited = mujoco.mjtLimited.mjLIMITED_FALSE
        _set_linear(tendon, "stiffness", k_sternum)
        _set_linear(tendon, "damping", c_sternum)
        rest = 2.0 * lat_front
        tendon.springlength = [rest, rest]
        tendon.wrap_site(f"{name}_left_front")
        tendon.wrap_site(f"{name}_right_front")
        out.tendons.append(f"{name}_sternum")
    _extend_keyframes(spec, model0, label, out.joints)
    return out


def _extend_keyframes(spec: mujoco.MjSpec, model0: mujoco.MjModel, label: str, joints: list) -> None:
    """Give each keyframe of the model the new hinges at 0 (the ribs as drawn): their qpos
    and qvel entries inserted where the compiled model puts them."""
    keys = [k for k in spec.keys if len(k.qpos) == model0.nq or len(k.qvel) == model0.nv]
    if not keys:
        return
    old = [(np.asarray(k.qpos, float), np.asarray(k.qvel, float)) for k in keys]
    for k in keys:  # compiled without them first, to learn where the new joints sit
        k.qpos, k.qvel = [], []
    model1 = compile_spec(spec, f"{label} with rigid.ribs")
    adr_q = sorted(int(model1.jnt_qposadr[model1.joint(j).id]) for j in joints)
    adr_v = sorted(int(model1.jnt_dofadr[model1.joint(j).id]) for j in joints)
    for k, (q, v) in zip(keys, old):
        if q.size == model0.nq:
            k.qpos = _insert_zeros(q, adr_q).tolist()
        if v.size == model0.nv:
            k.qvel = _insert_zeros(v, adr_v).tolist()


def _insert_zeros(x: np.ndarray, at_new: list) -> np.ndarray:
    """x with zeros placed so that they land at the (sorted) indices at_new of the result."""
    out = np.zeros(x.size + len(at_new))
    keep = np.setdiff1d(np.arange(out.size), at_new)
    out[keep] = x
    return out
