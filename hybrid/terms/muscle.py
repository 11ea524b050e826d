"""Muscle (paper 3.4): each muscular point attracted to the neighbours that lie
along the fibre direction, with a stiffness k_muscle(t) from a schedule."""

from __future__ import annotations

import math

import numpy as np

from .. import schedule as _sched
from ..errors import SceneError
from ..kernel import kernel
from .base import Rows, Term, force, param

__all__ = ["Muscle", "muscle_pairs", "add_muscle", "schedule_peak", "fibre_direction"]


@force("muscle")
class Muscle(Term):
    """Muscle (paper 3.4): each point of `region` is attracted to the
    neighbours lying along the fibre direction (within `max_angle_deg`),
    with stiffness k_muscle(t) (N/m) from `stiffness` (a number, a
    `Breathing` waveform, a `Table` or a function of time). Fibres run
    toward the point `toward_m`, or along `axis`."""

    formulations = ("paper",)  # a per-point parameter: its meaning changes with the mesh
    # mus_vert, mus_nbr (npair,) int32: each contraction pair; mus_sched (npair,) int64
    arrays = {"mus_vert": Rows(np.int32), "mus_nbr": Rows(np.int32), "mus_sched": Rows(np.int64)}
    region: object = param("selector")
    stiffness: object = param("schedule", ncomp=1, unit="N/m")
    toward_m: tuple = param("vec3", None)
    axis: tuple = param("vec3", None)
    max_angle_deg: float = param("angle_deg", 30.0)

    def compile(self, b, what):
        idx = super().compile(b, what)
        toward, axis = fibre_direction(self, what)
        angle = self.value("max_angle_deg", what)
        s = b.schedule(self.stiffness, f"{what}.stiffness", 1)
        mesh = b.mesh
        pv, pn = muscle_pairs(
            mesh.vert_pos, mesh.ring_ptr, mesh.ring_vert, idx, toward=toward, axis=axis, max_angle_deg=angle
        )
        if pv.size == 0:
            raise SceneError(
                f"{what}: no neighbour lies within {angle} deg of the fibre "
                f"direction; widen max_angle_deg or check toward_m/axis"
            )
        np.add.at(b.vert_stiffness, pv, schedule_peak(b.schedules[s]))
        b.add_rows(mus_vert=pv, mus_nbr=pn, mus_sched=np.full(pv.size, s))


def fibre_direction(term, what: str) -> tuple:
    """(toward_m, axis) of a muscle term, exactly one given, checked (the other None)."""
    if (term.toward_m is None) == (term.axis is None):
        raise SceneError(
            f"{what}: expected exactly one fibre direction, toward_m or axis, received "
            f"toward_m={term.toward_m!r} axis={term.axis!r}"
        )
    toward = term.value("toward_m", what)
    axis = term.value("axis", what)
    if axis is not None and not np.linalg.norm(axis) > 0:
        raise SceneError(f"{what}.axis: expected a non-zero vector, received {term.axis!r}")
    return toward, axis


def schedule_peak(s) -> float:
    """Largest value a scalar schedule takes (for stability estimates)."""
    if isinstance(s, _sched.Constant):
        return abs(float(np.asarray(s.value).reshape(-1)[0]))
    if isinstance(s, _sched.Breathing):
        return abs(s.peak)
    if isinstance(s, _sched.Table):
        return float(np.max(np.abs(np.asarray(s.value, float))))
    return 0.0  # a Python function: unknown ahead of time


def muscle_pairs(vert_pos, ring_ptr, ring_vert, verts, *, toward=None, axis=None, max_angle_deg: float = 30.0):
    """Neighbours each muscular point contracts toward (paper 3.4).

    A neighbour N of point P is a contraction target when the chord P->N lies
    within `max_angle_deg` of the fibre direction at P, either way along it:
    the fibre points from P toward the point `toward` (m), or along `axis`.
    Returns (pair_vert, pair_nbr) int32 arrays.
    """
    cos_min = math.cos(math.radians(max_angle_deg))
    pv, pn = [], []
    for i in verts:
        p = vert_pos[i]
        if toward is not None:
            u = np.asarray(toward, float) - p
            nu = np.linalg.norm(u)
            if nu == 0.0:  # the point the fibres converge to: every chord qualifies
                u = None
            else:
                u = u / nu
        else:
            u = np.asarray(axis, float) / np.linalg.norm(axis)
        for j in ring_vert[ring_ptr[i] : ring_ptr[i + 1]]:
            c = vert_pos[j] - p
            cos = 1.0 if u is None else abs(c @ u) / np.linalg.norm(c)
            if cos >= cos_min:
                pv.append(i)
                pn.append(j)
    return np.asarray(pv, np.int32), np.asarray(pn, np.int32)


@kernel
def add_muscle(mus_vert, mus_nbr, mus_sched, sched_val, vert_pos, vert_force):
    """Muscle (paper 3.4): F_i += k_muscle(t) (N_j - P_i) for each contraction pair.
    # Model: mus_vert, mus_nbr (np,) int32, mus_sched (np,) int64
    # Data in: sched_val (stiffness N/m in column 0), vert_pos
    # Data out: vert_force
    """
    for k in range(mus_vert.shape[0]):
        i = mus_vert[k]
        j = mus_nbr[k]
        c = sched_val[mus_sched[k], 0]
        vert_force[i, 0] += c * (vert_pos[j, 0] - vert_pos[i, 0])
        vert_force[i, 1] += c * (vert_pos[j, 1] - vert_pos[i, 1])
        vert_force[i, 2] += c * (vert_pos[j, 2] - vert_pos[i, 2])
