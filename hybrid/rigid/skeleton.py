"""A model's trunk skeleton read through MuJoCo: the rib cage, spine and pelvis meshes in the
world where the model starts (`hybrid.anatomy` fits the abdomen and diaphragm to them).

A bone's role comes from its geom's or mesh's name (case-insensitive), the pelvis's words
tried first, then the spine's, then the rib cage's ("thoracic12" is a vertebra, "thorax" and
"ribcage" the rib cage). Only mesh geoms count: a model drawn with capsules has no bone
surfaces to fit to, and is refused as a model without those bones. Geoms on the world body
(a floor, a logo) are never bones.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import mujoco
import numpy as np

from hybrid.errors import RigidError

from .controls import start_data
from .mjcf import compile_spec

__all__ = ["ROLES", "Bone", "Skeleton", "read_skeleton", "skeleton_of_spec", "thoracic_level"]

#: role -> the words a bone's geom or mesh name holds (a regular expression, case-insensitive);
#: in this order: the first role whose words match takes the bone
ROLES = {
    "pelvis": r"pelvis|sacrum|sacral|ilium|ischium|pubis|coxa|innominate|hip_?bone",
    "spine": r"lumbar|thoracic|vertebra|spine|(?<![a-z])[lt][0-9]{1,2}(?![0-9])",
    "rib_cage": r"rib|thorax",
}
#: what a refusal says each role needs
_WANT = {
    "rib_cage": "a rib cage (a mesh geom named with rib or thorax)",
    "spine": "a spine (mesh geoms named with lumbar, thoracic, vertebra, spine, L1..L5 or T1..T12)",
    "pelvis": "a pelvis (mesh geoms named with pelvis, sacrum, ilium, ischium, pubis or coxa)",
}


#: a thoracic vertebra's number in its geom's or mesh's name ("thoracic7", "T7")
_THORACIC = re.compile(r"thoracic_?([0-9]{1,2})(?![0-9])|(?<![a-z])t([0-9]{1,2})(?![0-9])", re.IGNORECASE)


def thoracic_level(*names: str) -> int | None:
    """The thoracic vertebra (1-12) a bone's names say it is, or None."""
    for n in names:
        m = _THORACIC.search(n or "")
        if m:
            level = int(m.group(1) or m.group(2))
            if 1 <= level <= 12:
                return level
    return None


@dataclass
class Bone:
    """One mesh geom of the skeleton: its role, geom, mesh and body names, and its triangle
    surface in the world where the model starts (vert (n, 3) m, face (m, 3))."""

    role: str
    geom: str
    mesh: str
    body: str
    vert: np.ndarray
    face: np.ndarray


@dataclass
class Skeleton:
    """The bones of a model by role (`ROLES`), and what was read (`label`)."""

    label: str
    bones: list = field(default_factory=list)
    free_root: bool = False  # a body on the world with a free joint (the scene fixes it)

    def of(self, role: str) -> list:
        return [b for b in self.bones if b.role == role]

    def points(self, role: str) -> np.ndarray:
        """The vertices (n, 3) m of every bone of `role`."""
        parts = [b.vert for b in self.of(role)]
        return np.concatenate(parts) if parts else np.zeros((0, 3))

    def thoracic(self) -> dict:
        """{level: the vertebra's centre (3,) m} for the spine's bones named T1..T12."""
        out = {}
        for b in self.of("spine"):
            level = thoracic_level(b.geom, b.mesh)
            if level is not None:
                out[level] = b.vert.mean(axis=0)
        return out

    def bodies(self, role: str) -> list:
        """The bodies that carry bones of `role`, in model order, each once."""
        return list(dict.fromkeys(b.body for b in self.of(role)))


def _role(*names: str) -> str | None:
    for role, words in ROLES.items():
        if any(re.search(words, n, flags=re.IGNORECASE) for n in names if n):
            return role
    return None


def skeleton_of_spec(spec: mujoco.MjSpec, label: str) -> Skeleton:
    """The bones (`Skeleton`) of the model `spec` (compiled here, the spec unchanged) at its
    start pose (qpos0). RigidError, one line naming `label` and every missing role, when it
    lacks a rib cage, a spine or a pelvis."""
    model = compile_spec(spec.copy() if hasattr(spec, "copy") else spec, label)
    data = start_data(model, -1)
    sk = Skeleton(label)
    sk.free_root = any(
        model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and model.body_parentid[model.jnt_bodyid[j]] == 0
        for j in range(model.njnt)
    )
    for g in range(model.ngeom):
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_MESH or model.geom_bodyid[g] == 0:
            continue
        mid = int(model.geom_dataid[g])
        geom = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
        mesh = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_MESH, mid) or ""
        role = _role(geom, mesh)
        if role is None:
            continue
        a, n = int(model.mesh_vertadr[mid]), int(model.mesh_vertnum[mid])
        fa, fn = int(model.mesh_faceadr[mid]), int(model.mesh_facenum[mid])
        rot = data.geom_xmat[g].reshape(3, 3)
        vert = model.mesh_vert[a : a + n].astype(float) @ rot.T + data.geom_xpos[g]
        body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[g])) or ""
        sk.bones.append(Bone(role, geom, mesh, body, vert, model.mesh_face[fa : fa + fn].astype(np.int64)))
    missing = [r for r in _WANT if not sk.of(r)]
    if missing:
        found = ", ".join(f"{r} ({len(sk.of(r))} meshes)" for r in _WANT if sk.of(r)) or "no bone meshes"
        raise RigidError(
            f"MJCF {label}: cannot fit a trunk to it: expected {'; '.join(_WANT[r] for r in missing)}; "
            f"received none ({found})"
        )
    return sk


def read_skeleton(mjcf: str, base_dir: str | None = None) -> Skeleton:
    """The bones of the model `mjcf`: "trunk", a path to an MJCF file (relative to
    `base_dir`), or "package:model" (e.g. "myo_sim:myotorso"), as `rigid.mjcf` names it."""
    from hybrid.scene import Masses, Rigid, Scene

    from .mjcf import load_rigid_spec

    scene = Scene(masses=Masses(total_kg=1.0), rigid=Rigid(mjcf=str(mjcf)), base_dir=base_dir)
    spec, label, _ = load_rigid_spec(scene)
    return skeleton_of_spec(spec, label)
