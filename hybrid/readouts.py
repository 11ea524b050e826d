"""What a state says beyond positions: the membrane's internal forces and their
net force and moment, its elastic energy, the volume a region swept, and a rigid
body's pitch from its recorded orientations.

Read on demand by `Simulation` (never inside the step): each sums the same
compiled kernels the step calls, on the state's positions.
"""

from __future__ import annotations

import numpy as np

from .mesh.geometry import region_faces
from .model import MembraneArrays
from .terms import Membrane, MassSpring, Muscle, MuscleFibres, PassiveFibres, ShapeMemory
from .terms.fibres import add_muscle_fibres
from .terms.passive_fibres import add_passive_fibres, passive_fibres_energy
from .terms.membrane import add_membrane_serial, membrane_energy
from .terms.muscle import add_muscle
from .terms.shape_memory import add_shape_memory
from .terms.springs import add_mass_spring

__all__ = ["internal_forces", "net_internal", "elastic_energy", "region_faces", "swept_volume", "quat_rot", "pitch_deg"]

#: terms whose forces are internal to the membrane (between its points)
INTERNAL_TERMS = (Membrane, ShapeMemory, Muscle, MassSpring, MuscleFibres, PassiveFibres)
#: internal terms that are no energy's gradient (paper formulation)
NON_CONSERVATIVE = (ShapeMemory, Muscle)


def internal_forces(a: MembraneArrays, vert_pos: np.ndarray, sched_val: np.ndarray) -> np.ndarray:
    """(nvert, 3) N: the forces of the internal terms the model has (elasticity,
    muscle, springs) at vert_pos, the muscles' schedules at their values sched_val."""
    f = np.zeros_like(vert_pos)
    on = a.term_on
    if on[Membrane.id]:
        add_membrane_serial(a.mem_vert, a.mem_par, False, vert_pos, np.zeros_like(vert_pos), f)
    if on[ShapeMemory.id]:
        sums = np.zeros((a.sm_vert.shape[0], 9))
        add_shape_memory(a.sm_vert, a.sm_stiff, a.sm_coef, a.ring_ptr, a.ring_vert, a.ring_closed, vert_pos,
                         sums, f)
    if on[Muscle.id]:
        add_muscle(a.mus_vert, a.mus_nbr, a.mus_sched, sched_val, vert_pos, f)
    if on[MassSpring.id]:
        add_mass_spring(a.spring_vert, a.spring_stiff, a.spring_rest, vert_pos, f)
    if on[MuscleFibres.id]:
        add_muscle_fibres(a.fib_vert, a.fib_par, a.fib_sched, sched_val, vert_pos, f)
    if on[PassiveFibres.id]:
        add_passive_fibres(a.pf_vert, a.pf_par, vert_pos, f)
    return f


def net_internal(vert_pos: np.ndarray, force: np.ndarray) -> dict:
    """Net force (N) and net moment about the centroid (N m) of the point forces
    `force`, with the sums of |F| and |r x F| they are small against."""
    r = vert_pos - vert_pos.mean(axis=0)
    rxf = np.cross(r, force)
    return {"net_force_n": force.sum(axis=0), "net_moment_n_m": rxf.sum(axis=0),
            "sum_abs_force_n": float(np.linalg.norm(force, axis=1).sum()),
            "sum_abs_moment_n_m": float(np.linalg.norm(rxf, axis=1).sum())}


def elastic_energy(a: MembraneArrays, vert_pos: np.ndarray) -> float | None:
    """The elastic energy (J) of the membrane's conservative terms (the muscle fibres'
    active work is not counted); None when an elastic or muscle term of the paper
    formulation has no energy."""
    if any(a.term_on[cls.id] for cls in NON_CONSERVATIVE):
        return None
    e = 0.0
    if a.term_on[Membrane.id]:
        e += membrane_energy(a.mem_vert, a.mem_par, vert_pos)
    if a.term_on[PassiveFibres.id]:
        e += passive_fibres_energy(a.pf_vert, a.pf_par, vert_pos)
    if a.term_on[MassSpring.id]:
        p = vert_pos[a.spring_vert]
        stretch = np.linalg.norm(p[:, 1] - p[:, 0], axis=1) - a.spring_rest
        e += float(0.5 * (a.spring_stiff * stretch ** 2).sum())
    return float(e)


def swept_volume(face_vert: np.ndarray, rest: np.ndarray, pos: np.ndarray) -> float:
    """Volume (m^3) the faces face_vert swept moving straight from `rest` to `pos`,
    positive outward: sum over faces of the mean displacement dotted with the
    time integral of the area vector, exact for straight paths, independent of
    the origin; over a closed surface it is V(pos) - V(rest) exactly."""
    X, x = rest[face_vert], pos[face_vert]
    d = x - X
    E1, E2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    d1, d2 = d[:, 1] - d[:, 0], d[:, 2] - d[:, 0]
    # the area vector N(s) = (E1 + s d1) x (E2 + s d2) / 2 integrated over s in [0, 1]
    n = 0.5 * (np.cross(E1, E2) + 0.5 * (np.cross(E1, d2) + np.cross(d1, E2)) + np.cross(d1, d2) / 3.0)
    return float(np.einsum("ij,ij->", d.mean(axis=1), n))


def quat_rot(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of unit quaternions q (n, 4), w first."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)


def pitch_deg(quat: np.ndarray, axis_body: np.ndarray, anterior: np.ndarray, cranial: np.ndarray) -> np.ndarray:
    """The pitch (deg) of a body whose orientations are quat (n, 4): the elevation of its
    anterior axis (axis_body, in its own frame) toward cranial, positive when it turns up."""
    a = quat_rot(quat) @ axis_body
    return np.degrees(np.arctan2(a @ cranial, a @ anterior))
