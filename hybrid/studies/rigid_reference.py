"""The paper's own rigid-body algorithm (section 3.5, steps 4-7), as a pure-numpy reference.

Promayon, Baconnier & Puech (1997) move a rigid region R_r, with position C_r (its
centre of mass when no point is nailed) and orientation q_r, as follows:

4. the total force F_r = sum_i F_r^i (the paper prints sum_i F_r^i / m_i, which is not
   a force; we read it as the sum of the forces, and the acceleration as F_r / M);
5. the total torque about C_r, T_r = sum_i (P_r^i - C_r) x F_r^i;
6. integrate C_r and q_r with explicit Euler;
7. the points' new positions and velocities follow from the body's pose and twist.

Step 6 here, all right-hand sides taken at the old state (forward Euler):

    C   += h v                      v += h F / M
    q   += h/2 (0, w) (x) q,  then q /= |q|     (w: angular velocity, world frame)
    w   += h I_w^-1 (T - w x I_w w),  I_w = R(q) I_body R(q)^T   (Euler's equations)

It is first order in h. `run_paper` and `run_mujoco` move the same free body (no
gravity, no contact) under a constant force fixed in the body at a body-fixed point,
so that their final states can be compared (tests/studies/test_rigid_reference.py: order of convergence
as h halves, against MuJoCo's RK4 at a much smaller step).

Conventions: quaternions (w, x, y, z), body -> world, as MuJoCo. SI units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "RigidBody",
    "RigidState",
    "quat_mul",
    "quat_to_mat",
    "point_wrench",
    "paper_step",
    "paper_points",
    "run_paper",
    "run_mujoco",
    "state_error",
]


@dataclass(frozen=True)
class RigidBody:
    """Mass properties of a rigid body.

    mass : kg
    inertia : (3,) kg m^2, principal moments about the centre of mass (body frame)
    """

    mass: float
    inertia: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "inertia", np.asarray(self.inertia, dtype=float).reshape(3))


@dataclass
class RigidState:
    """Pose and twist of a rigid body.

    pos : (3,) m, centre of mass C_r          vel : (3,) m/s, its velocity
    quat : (4,) orientation q_r (w, x, y, z)  omega : (3,) rad/s, angular velocity (world)
    """

    pos: np.ndarray = field(default_factory=lambda: np.zeros(3))
    vel: np.ndarray = field(default_factory=lambda: np.zeros(3))
    quat: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0, 0.0]))
    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def copy(self) -> RigidState:
        return RigidState(self.pos.copy(), self.vel.copy(), self.quat.copy(), self.omega.copy())


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a (x) b of (4,) quaternions (w, x, y, z)."""
    aw, av = a[0], a[1:]
    bw, bv = b[0], b[1:]
    return np.concatenate(([aw * bw - av @ bv], aw * bv + bw * av + np.cross(av, bv)))


def quat_to_mat(q: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix (body -> world) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def point_wrench(center: np.ndarray, points: np.ndarray, forces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steps 4-5: total force (3,) N and torque (3,) N m about `center` (3,) m.

    points : (n, 3) m, world positions of the points;  forces : (n, 3) N on them.
    """
    points = np.atleast_2d(points)
    forces = np.atleast_2d(forces)
    return forces.sum(axis=0), np.cross(points - center, forces).sum(axis=0)


def paper_step(body: RigidBody, state: RigidState, force: np.ndarray, torque: np.ndarray, h: float) -> RigidState:
    """Step 6: one explicit Euler step of length h (s) under force (N) and torque (N m)."""
    rot = quat_to_mat(state.quat)
    inertia_w = rot @ np.diag(body.inertia) @ rot.T
    w = state.omega
    domega = np.linalg.solve(inertia_w, torque - np.cross(w, inertia_w @ w))
    quat = state.quat + 0.5 * h * quat_mul(np.concatenate(([0.0], w)), state.quat)
    return RigidState(
        pos=state.pos + h * state.vel,
        vel=state.vel + h * np.asarray(force) / body.mass,
        quat=quat / np.linalg.norm(quat),
        omega=w + h * domega,
    )


def paper_points(state: RigidState, points_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Step 7: world positions (n, 3) m and velocities (n, 3) m/s of body-fixed points.

    points_body : (n, 3) m, coordinates in the body frame (origin at the centre of mass).
    """
    arm = np.atleast_2d(points_body) @ quat_to_mat(state.quat).T
    return state.pos + arm, state.vel + np.cross(state.omega, arm)


def _nsteps(h: float, duration: float) -> int:
    n = int(round(duration / h))
    if n < 1 or abs(n * h - duration) > 1e-9 * duration:
        raise ValueError(f"duration: expected a whole number of steps of h = {h} s, got {duration} s")
    return n


def run_paper(
    body: RigidBody, state0: RigidState, point_body: np.ndarray, force_body: np.ndarray, h: float, duration: float
) -> RigidState:
    """Move a free body with the paper's algorithm under a body-fixed point force.

    point_body : (3,) m and force_body : (3,) N, both fixed in the body frame.
    Returns the state after `duration` s (a whole number of steps h).
    """
    point_body = np.asarray(point_body, dtype=float)
    force_body = np.asarray(force_body, dtype=float)
    state = state0.copy()
    for _ in range(_nsteps(h, duration)):
        rot = quat_to_mat(state.quat)
        points, _ = paper_points(state, point_body)  # step 7 of the last step
        force, torque = point_wrench(state.pos, points, rot @ force_body)  # steps 4-5
        state = paper_step(body, state, force, torque, h)  # step 6
    return state


def run_mujoco(
    body: RigidBody,
    state0: RigidState,
    point_body: np.ndarray,
    force_body: np.ndarray,
    h: float,
    duration: float,
    integrator: str = "RK4",
) -> RigidState:
    """The same free body moved by MuJoCo (through `hybrid.rigid`).

    The body-fixed force is a site actuator (`hybrid.rigid.free_body_spec`), which
    MuJoCo evaluates at every stage of its integrator.
    """
    from hybrid import rigid  # MuJoCo only when asked for

    force_body = np.asarray(force_body, dtype=float)
    spec = rigid.free_body_spec(body.mass, body.inertia, point_body, force_body, integrator=integrator, timestep=h)
    system = rigid.RigidSystem(spec)
    d = system.data
    d.qpos[0:3] = state0.pos
    d.qpos[3:7] = state0.quat
    d.qvel[0:3] = state0.vel
    d.qvel[3:6] = quat_to_mat(state0.quat).T @ state0.omega  # free joint: body frame
    d.ctrl[0] = np.linalg.norm(force_body)
    system.forward()
    for _ in range(_nsteps(h, duration)):
        system.step()
    quat = d.qpos[3:7].copy()
    return RigidState(pos=d.qpos[0:3].copy(), vel=d.qvel[0:3].copy(), quat=quat, omega=quat_to_mat(quat) @ d.qvel[3:6])


def state_error(a: RigidState, b: RigidState) -> dict[str, float]:
    """Differences between two states: pos (m), angle (rad), vel (m/s), omega (rad/s)."""
    dq = quat_mul(np.array([a.quat[0], *(-a.quat[1:])]), b.quat)
    angle = 2.0 * np.arctan2(np.linalg.norm(dq[1:]), abs(dq[0]))
    return {
        "pos": float(np.linalg.norm(a.pos - b.pos)),
        "angle": float(angle),
        "vel": float(np.linalg.norm(a.vel - b.vel)),
        "omega": float(np.linalg.norm(a.omega - b.omega)),
    }
