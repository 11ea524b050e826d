"""What a state says beyond positions: the membrane's internal forces and their
net force and moment, its elastic energy, the volume a region swept, and a rigid
body's pitch from its recorded orientations.

Read on demand by `Simulation` (never inside the step): each sums the same
compiled kernels the step calls, on the state's positions.
"""

from __future__ import annotations

import numpy as np

from .kernel import jit
from .mesh.geometry import region_faces
from .model import MembraneArrays
from .terms import MassSpring, Membrane, Muscle, MuscleFibres, PassiveFibres, ShapeMemory
from .terms.fibres import add_muscle_fibres
from .terms.membrane import add_membrane_serial, membrane_energy
from .terms.muscle import add_muscle
from .terms.passive_fibres import add_passive_fibres, passive_fibres_energy
from .terms.shape_memory import add_shape_memory
from .terms.springs import add_mass_spring

__all__ = [
    "internal_forces",
    "net_internal",
    "elastic_energy",
    "region_faces",
    "swept_volume",
    "swept_volumes",
    "quat_rot",
    "pitch_deg",
]

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
        add_shape_memory(a.sm_vert, a.sm_stiff, a.sm_coef, a.ring_ptr, a.ring_vert, a.ring_closed, vert_pos, sums, f)
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
    return {
        "net_force_n": force.sum(axis=0),
        "net_moment_n_m": rxf.sum(axis=0),
        "sum_abs_force_n": float(np.linalg.norm(force, axis=1).sum()),
        "sum_abs_moment_n_m": float(np.linalg.norm(rxf, axis=1).sum()),
    }


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
        e += float(0.5 * (a.spring_stiff * stretch**2).sum())
    return float(e)


def swept_volume(face_vert: np.ndarray, rest: np.ndarray, pos: np.ndarray) -> float:
    """Volume (m^3) the faces face_vert swept moving straight from `rest` to `pos`,
    positive outward: sum over faces of the mean displacement dotted with the
    time integral of the area vector, exact for straight paths, independent of
    the origin; over a closed surface it is V(pos) - V(rest) exactly."""
    return float(swept_volumes(face_vert, rest, pos[None])[0])


def swept_volumes(face_vert: np.ndarray, rest: np.ndarray, pos_frames: np.ndarray) -> np.ndarray:
    """`swept_volume` of each frame of pos_frames (nframe, nvert, 3): (nframe,) m^3.
    Compiled: a run reads it every frame, where numpy's temporaries cost a quarter
    of an implicit step at 5,000 points."""
    return _swept_volumes(
        np.ascontiguousarray(face_vert, np.int64),
        np.ascontiguousarray(rest, float),
        np.ascontiguousarray(pos_frames, float),
    )


@jit
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@jit
def _swept_volumes(face_vert, rest, pos_frames):
    out = np.zeros(pos_frames.shape[0])
    for f in range(pos_frames.shape[0]):
        pos = pos_frames[f]
        total = 0.0
        for k in range(face_vert.shape[0]):
            a, b, c = face_vert[k, 0], face_vert[k, 1], face_vert[k, 2]
            dax, day, daz = pos[a, 0] - rest[a, 0], pos[a, 1] - rest[a, 1], pos[a, 2] - rest[a, 2]
            dbx, dby, dbz = pos[b, 0] - rest[b, 0], pos[b, 1] - rest[b, 1], pos[b, 2] - rest[b, 2]
            dcx, dcy, dcz = pos[c, 0] - rest[c, 0], pos[c, 1] - rest[c, 1], pos[c, 2] - rest[c, 2]
            E1x, E1y, E1z = rest[b, 0] - rest[a, 0], rest[b, 1] - rest[a, 1], rest[b, 2] - rest[a, 2]
            E2x, E2y, E2z = rest[c, 0] - rest[a, 0], rest[c, 1] - rest[a, 1], rest[c, 2] - rest[a, 2]
            e1x, e1y, e1z = dbx - dax, dby - day, dbz - daz
            e2x, e2y, e2z = dcx - dax, dcy - day, dcz - daz
            # the area vector N(s) = (E1 + s e1) x (E2 + s e2) / 2 integrated over s in [0, 1]
            n0 = _cross(E1x, E1y, E1z, E2x, E2y, E2z)
            n1 = _cross(E1x, E1y, E1z, e2x, e2y, e2z)
            n2 = _cross(e1x, e1y, e1z, E2x, E2y, E2z)
            n3 = _cross(e1x, e1y, e1z, e2x, e2y, e2z)
            nx = 0.5 * (n0[0] + 0.5 * (n1[0] + n2[0]) + n3[0] / 3.0)
            ny = 0.5 * (n0[1] + 0.5 * (n1[1] + n2[1]) + n3[1] / 3.0)
            nz = 0.5 * (n0[2] + 0.5 * (n1[2] + n2[2]) + n3[2] / 3.0)
            total += ((dax + dbx + dcx) * nx + (day + dby + dcy) * ny + (daz + dbz + dcz) * nz) / 3.0
        out[f] = total
    return out


def quat_rot(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of unit quaternions q (n, 4), w first."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        1,
    )


def pitch_deg(quat: np.ndarray, axis_body: np.ndarray, anterior: np.ndarray, cranial: np.ndarray) -> np.ndarray:
    """The pitch (deg) of a body whose orientations are quat (n, 4): the elevation of its
    anterior axis (axis_body, in its own frame) toward cranial, positive when it turns up."""
    a = quat_rot(quat) @ axis_body
    return np.degrees(np.arctan2(a @ cranial, a @ anterior))


def ring_faces(face_vert: np.ndarray, vert: int, rings: int) -> np.ndarray:
    """The faces within `rings` rings of point `vert` (indices into face_vert): 1, the faces
    that meet at it; 2, those that meet at its neighbours too; and so on."""
    near = np.zeros(int(face_vert.max()) + 1, bool)
    near[vert] = True
    for _ in range(rings - 1):
        near[face_vert[near[face_vert].any(axis=1)].ravel()] = True
    return np.nonzero(near[face_vert].any(axis=1))[0]


def axis_crossing_z(face_vert: np.ndarray, pos_frames: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """The height (m) at which the surface `face_vert` crosses the vertical line through
    `xy` (2,) in each frame of pos_frames (k, nvert, 3): the highest crossing, linear in
    the face it crosses; NaN for a frame whose faces miss the line. A surface's height,
    which converges as the mesh is refined, not one mesh point's."""
    a, b, c = (pos_frames[:, face_vert[:, j]] for j in range(3))  # (k, nface, 3)
    e1, e2, p = b[..., :2] - a[..., :2], c[..., :2] - a[..., :2], xy - a[..., :2]
    det = e1[..., 0] * e2[..., 1] - e2[..., 0] * e1[..., 1]
    tol = 1e-12  # a line through a corner or along an edge belongs to every face that meets there
    with np.errstate(divide="ignore", invalid="ignore"):  # a face seen edge-on (det 0) is no crossing
        u = (p[..., 0] * e2[..., 1] - e2[..., 0] * p[..., 1]) / det
        w = (e1[..., 0] * p[..., 1] - p[..., 0] * e1[..., 1]) / det
        inside = (det != 0) & (u >= -tol) & (w >= -tol) & (u + w <= 1 + tol)
        z = np.where(inside, a[..., 2] + u * (b[..., 2] - a[..., 2]) + w * (c[..., 2] - a[..., 2]), -np.inf)
    top = z.max(axis=1) if z.shape[1] else np.full(len(pos_frames), -np.inf)
    return np.where(np.isfinite(top), top, np.nan)
