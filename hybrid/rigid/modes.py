"""The rigid part's own stable step (`hybrid inspect`, and a warning at the start of `hybrid run`).

MuJoCo's integrators take springs explicitly: joint stiffness and tendon stiffness (the ribs'
hinges and sternal springs). Linearized at the model's start, the undamped motions are the modes
of K phi = omega^2 M phi (M the joint-space inertia, `mj_fullM`; K the joints' stiffness plus each
tendon's k J^T J). One Euler step of a mode of damping rate b (phi^T B phi, the joints' damping,
which MuJoCo's Euler takes implicitly, and the tendons' and everything else's under implicit and
implicitfast) maps (x, v) to

    v' = (v - h omega^2 x) / (1 + h b),    x' = x + h v',

stable while (h omega)^2 < 4 + 2 h b: h omega < 2 undamped. RK4: h omega < 2 sqrt(2) (its
stability region on the imaginary axis), damping left out. The estimate is the largest h stable
for every mode. It leaves out gravity's stiffness, the membrane's pull on the linked bodies and the
lungs' pleural load on the bodies that carry the cavity: it is the step above which the rigid part
diverges alone, not a promise below it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["RigidModes", "rigid_modes", "implicit_joint_damping"]

_SPRUNG = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


@dataclass(frozen=True)
class RigidModes:
    """The rigid part's fastest sprung mode and its largest stable step (module docstring):
    omega_rad_s, its angular frequency; damping_rate_per_s, its damping rate b; dt_stable_s,
    the largest stable step of every mode (inf: no spring); joints, the joints that move most
    in the limiting mode (those within half of its largest); integrator, MuJoCo's."""

    omega_rad_s: float
    damping_rate_per_s: float
    dt_stable_s: float
    joints: tuple
    integrator: str

    def line(self, dt_s: float) -> str:
        """One line for `hybrid inspect` and the run's warning."""
        if not math.isfinite(self.dt_stable_s):
            return "rigid stable-step estimate: none (no joint or tendon springs)"
        return (
            f"rigid stable-step estimate {self.dt_stable_s:.3g} s ({self.integrator}; its fastest "
            f"sprung mode {self.omega_rad_s:.3g} rad/s, damping rate {self.damping_rate_per_s:.3g}/s, "
            f"in {', '.join(self.joints)}; h omega {dt_s * self.omega_rad_s:.2f})"
        )


def _tendon_jacobian(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """(ntendon, nv): each tendon's length's gradient in the joints' velocities (sparse in MuJoCo)."""
    jac = np.zeros((model.ntendon, model.nv))
    for t in range(model.ntendon):
        a, n = model.ten_J_rowadr[t], model.ten_J_rownnz[t]
        jac[t, model.ten_J_colind[a : a + n]] = data.ten_J[a : a + n]
    return jac


def implicit_joint_damping(model: mujoco.MjModel) -> np.ndarray:
    """(nv,) N m s/rad (or N s/m): the joints' damping that MuJoCo's step takes implicitly, the
    dof damping unless Euler's implicit damping is disabled (`mjDSBL_EULERDAMP`)."""
    euler = int(model.opt.integrator) == int(mujoco.mjtIntegrator.mjINT_EULER)
    if euler and int(model.opt.disableflags) & int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP):
        return np.zeros(model.nv)
    return np.array(model.dof_damping, float)


def _stable_step(omega: float, b: float, rk4: bool) -> float:
    """The largest h with (h omega)^2 < 4 + 2 h b (RK4: h omega < 2 sqrt 2)."""
    if omega <= 0.0:
        return math.inf
    if rk4:
        return 2.0 * math.sqrt(2.0) / omega
    # the positive root of omega^2 h^2 - 2 b h - 4 = 0
    return (b + math.sqrt(b * b + 4.0 * omega * omega)) / (omega * omega)


def rigid_modes(model: mujoco.MjModel, data: mujoco.MjData | None = None) -> RigidModes:
    """The fastest sprung mode and the largest stable step of `model` (module docstring), at
    data's state (None: the model's start, qpos0)."""
    from .describe import _INTEGRATOR

    if data is None:
        data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    nv = model.nv
    integrator = _INTEGRATOR.get(int(model.opt.integrator), str(int(model.opt.integrator)))
    if nv == 0:
        return RigidModes(0.0, 0.0, math.inf, (), integrator)
    inertia = np.zeros((nv, nv))
    mujoco.mj_fullM(model, data, inertia)
    stiffness, damping = np.zeros((nv, nv)), np.diag(implicit_joint_damping(model))
    euler = int(model.opt.integrator) == int(mujoco.mjtIntegrator.mjINT_EULER)
    for j in range(model.njnt):
        if int(model.jnt_type[j]) in _SPRUNG:
            stiffness[model.jnt_dofadr[j], model.jnt_dofadr[j]] += model.jnt_stiffness[j]
    jac = _tendon_jacobian(model, data)
    for t in range(model.ntendon):
        stiffness += model.tendon_stiffness[t] * np.outer(jac[t], jac[t])
        if not euler:  # implicit, implicitfast: every velocity force implicit; Euler: the joints' only
            damping += model.tendon_damping[t] * np.outer(jac[t], jac[t])
    if not stiffness.any():
        return RigidModes(0.0, 0.0, math.inf, (), integrator)
    # K phi = omega^2 M phi through M = L L^T: (L^-1 K L^-T) y = omega^2 y, phi = L^-T y (phi^T M phi = 1)
    low = np.linalg.cholesky(inertia)
    half = np.linalg.solve(low, stiffness)
    omega2, ys = np.linalg.eigh(np.linalg.solve(low, half.T).T)
    shapes = np.linalg.solve(low.T, ys)
    rk4 = int(model.opt.integrator) == int(mujoco.mjtIntegrator.mjINT_RK4)
    best = None
    for i in range(nv):
        omega = math.sqrt(max(float(omega2[i]), 0.0))
        phi = shapes[:, i]
        b = float(phi @ damping @ phi)
        h = _stable_step(omega, b, rk4)
        if best is None or h < best[0]:
            best = (h, omega, b, phi)
    h, omega, b, phi = best
    moving = np.abs(phi) >= 0.5 * np.abs(phi).max()
    joints = tuple(model.joint(j).name or f"joint {j}" for j in range(model.njnt) if moving[model.jnt_dofadr[j]])
    return RigidModes(omega, b, h, joints, integrator)
