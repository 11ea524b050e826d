"""Forces between a point and a target or a neighbour: applied forces,
attractive points (paper 3.3) and the mass-spring network (paper 6.1)."""

from __future__ import annotations

import math

import numpy as np

from .. import checks
from ..errors import SceneError
from ..kernel import kernel
from .base import Rows, Term, force, param

__all__ = ["MassSpring", "AppliedForce", "Attraction", "add_mass_spring", "add_applied", "add_attraction"]


@force("mass_spring")
class MassSpring(Term):
    """Springs along the mesh edges within `region` (the paper's comparison model)."""

    formulations = ("paper",)  # a per-point parameter: its meaning changes with the mesh
    # spring_vert (ns, 2) int32; spring_stiff (ns,) N/m; spring_rest (ns,) m
    arrays = {"spring_vert": Rows(np.int32, 2), "spring_stiff": Rows(float), "spring_rest": Rows(float)}
    stiffness_n_per_m: float = param("positive", hi=checks.MAX_STIFFNESS_N_PER_M)
    region: object = param("selector", "all")

    def compile(self, b, what):
        idx = super().compile(b, what)
        k = self.value("stiffness_n_per_m", what)
        inside = np.zeros(b.mesh.nvert, bool)
        inside[idx] = True
        for e in np.nonzero(inside[b.mesh.edge_vert].all(axis=1))[0]:
            b.rows["mass_spring"].append((int(e), k))

    @classmethod
    def finish(cls, b):
        stiff_by_edge = dict(b.rows["mass_spring"])  # a later term wins where regions overlap
        mesh = b.mesh
        eidx = np.array(sorted(stiff_by_edge), dtype=np.int64)
        stiff = np.array([stiff_by_edge[int(e)] for e in eidx])
        np.add.at(b.vert_stiffness, mesh.edge_vert[eidx, 0], stiff)  # each point's own stiffness,
        np.add.at(b.vert_stiffness, mesh.edge_vert[eidx, 1], stiff)  # whatever its neighbours do
        used = b.moving[mesh.edge_vert[eidx]].any(axis=1)
        spring_vert = mesh.edge_vert[eidx[used]].astype(np.int32)
        b.out["spring_vert"] = spring_vert
        b.out["spring_stiff"] = stiff[used]
        b.out["spring_rest"] = np.linalg.norm(
            mesh.vert_pos[spring_vert[:, 1]] - mesh.vert_pos[spring_vert[:, 0]], axis=1
        )


@force("applied_force")
class AppliedForce(Term):
    """A force (N) on each point of `region`: a 3-vector, a `Table` or a function of time."""

    formulations = ("paper",)  # a per-point parameter: its meaning changes with the mesh
    # app_vert (n,) int32; app_sched (n,) int64: each point's schedule row
    arrays = {"app_vert": Rows(np.int32), "app_sched": Rows(np.int64)}
    region: object = param("selector")
    force_n: object = param("schedule", ncomp=3)

    def compile(self, b, what):
        idx = super().compile(b, what)
        s = b.schedule(self.force_n, f"{what}.force_n", 3)
        b.add_rows(app_vert=idx, app_sched=np.full(idx.size, s))


@force("attraction")
class Attraction(Term):
    """Attractive points (paper 3.3): a spring (N/m) from each point of
    `region` to its ideal position = rest position (or `target_m`) plus
    `offset_m` (a 3-vector, `Table` or function of time, for moving targets)."""

    formulations = ("paper",)  # a per-point parameter: its meaning changes with the mesh
    # att_vert (n,) int32; att_stiff (n,) N/m; att_target (n, 3) m; att_sched (n,) int64 (offsets)
    arrays = {
        "att_vert": Rows(np.int32),
        "att_stiff": Rows(float),
        "att_target": Rows(float, 3),
        "att_sched": Rows(np.int64),
    }
    region: object = param("selector")
    stiffness_n_per_m: float = param("positive", hi=checks.MAX_STIFFNESS_N_PER_M)
    offset_m: object = param("schedule", (0.0, 0.0, 0.0), ncomp=3)
    target_m: tuple = param("target", None)

    def compile(self, b, what):
        idx = super().compile(b, what)
        k = self.value("stiffness_n_per_m", what)
        if self.target_m is None:
            target = b.mesh.vert_pos[idx]
        else:
            target = np.asarray(self.target_m, dtype=float)
            if target.shape == (3,):
                target = np.tile(target, (idx.size, 1))
            if target.shape != (idx.size, 3) or not np.all(np.isfinite(target)):
                raise SceneError(
                    f"{what}.target_m: expected a 3-vector or {idx.size} 3-vectors, "
                    f"received shape {np.shape(self.target_m)}"
                )
        s = b.schedule(self.offset_m, f"{what}.offset_m", 3)
        b.add_rows(att_vert=idx, att_stiff=np.full(idx.size, k), att_target=target, att_sched=np.full(idx.size, s))
        b.vert_stiffness[idx] += k


# ---------------------------------------------------------------- kernels


@kernel
def add_applied(app_vert, app_sched, sched_val, vert_force):
    """F_i += f_s(t): a force per vertex from schedule s.
    # Model: app_vert (n,) int32, app_sched (n,) int64
    # Data in: sched_val (nsched, 3) N (schedules at time t)
    # Data out: vert_force
    """
    for k in range(app_vert.shape[0]):
        i = app_vert[k]
        s = app_sched[k]
        vert_force[i, 0] += sched_val[s, 0]
        vert_force[i, 1] += sched_val[s, 1]
        vert_force[i, 2] += sched_val[s, 2]


@kernel
def add_attraction(att_vert, att_stiff, att_target, att_sched, sched_val, vert_pos, vert_force):
    """F_i += k (P_ideal - P_i), P_ideal = target_i + offset_s(t) (paper 3.3).
    # Model: att_vert (n,) int32, att_stiff (n,) N/m, att_target (n, 3) m, att_sched (n,) int64
    # Data in: sched_val (offsets, m), vert_pos (nvert, 3) m
    # Data out: vert_force
    """
    for k in range(att_vert.shape[0]):
        i = att_vert[k]
        s = att_sched[k]
        c = att_stiff[k]
        for a in range(3):
            vert_force[i, a] += c * (att_target[k, a] + sched_val[s, a] - vert_pos[i, a])


@kernel
def add_mass_spring(spring_vert, spring_stiff, spring_rest, vert_pos, vert_force):
    """Springs between neighbours (the paper's comparison model, 6.1).
    # Model: spring_vert (ns, 2) int32, spring_stiff (ns,) N/m, spring_rest (ns,) m
    # Data in: vert_pos
    # Data out: vert_force (both ends)
    """
    for s in range(spring_vert.shape[0]):
        a, b = spring_vert[s, 0], spring_vert[s, 1]
        dx = vert_pos[b, 0] - vert_pos[a, 0]
        dy = vert_pos[b, 1] - vert_pos[a, 1]
        dz = vert_pos[b, 2] - vert_pos[a, 2]
        ln = math.sqrt(dx * dx + dy * dy + dz * dz)
        f = spring_stiff[s] * (ln - spring_rest[s]) / ln
        vert_force[a, 0] += f * dx
        vert_force[a, 1] += f * dy
        vert_force[a, 2] += f * dz
        vert_force[b, 0] -= f * dx
        vert_force[b, 1] -= f * dy
        vert_force[b, 2] -= f * dz
