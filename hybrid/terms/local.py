"""Constraints on single points: nailed points, prescribed trajectories and
keep-in regions (paper 4). Nailed, prescribed and rigidly linked points are
never integrated; keep-in projects the integrated points back into a region.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

from .. import checks
from ..errors import SceneError
from ..kernel import kernel
from .base import Rows, Term, claim_points, constraint, param

__all__ = ["Nailed", "Prescribed", "KeepIn", "KeepInShape", "apply_prescribed", "apply_keep_in"]


class KeepInShape(IntEnum):
    """The shapes of a keep-in region (`MembraneArrays.shape_kind`)."""

    HALF_SPACE = 0
    BALL = 1
    BOX = 2


@constraint("nailed", flag=False)
class Nailed(Term):
    """Points fixed at their rest positions (spine, pelvis...)."""

    region: object = param("selector")

    def compile(self, b, what):
        idx = b.region(self.region, f"{what}.region")
        claim_points(b.claims, idx, "nailed", what)
        b.vert_free[idx] = 0


@constraint("prescribed")
class Prescribed(Term):
    """Points that follow rest position + `displacement_m`(t) (m)."""

    # pre_vert (n,) int32; pre_rest (n, 3) m; pre_sched (n,) int64
    arrays = {"pre_vert": Rows(np.int32), "pre_rest": Rows(float, 3), "pre_sched": Rows(np.int64)}
    region: object = param("selector")
    displacement_m: object = param("schedule", ncomp=3)

    def compile(self, b, what):
        idx = super().compile(b, what)
        s = b.schedule(self.displacement_m, f"{what}.displacement_m", 3)
        claim_points(b.claims, idx, "prescribed", what)
        b.vert_free[idx] = 0
        b.add_rows(pre_vert=idx, pre_rest=b.mesh.vert_pos[idx], pre_sched=np.full(idx.size, s))


@constraint("keep_in")
class KeepIn(Term):
    """Points kept inside a half-space (`point_m`, `normal` pointing inside),
    a ball (`center_m`, `radius_m`) or a box (`lo_m`, `hi_m`)."""

    # kin_vert (n,) int32; kin_shape (n,) int64: row of shape_kind / shape_par;
    # shape_kind (ns,) int64 KeepInShape; shape_par (ns, 6) m (see apply_keep_in)
    arrays = {
        "kin_vert": Rows(np.int32),
        "kin_shape": Rows(np.int64),
        "shape_kind": Rows(np.int64),
        "shape_par": Rows(float, 6),
    }
    region: object = param("selector")
    shape: str = param("choice", choices=("half_space", "ball", "box"))
    point_m: tuple = param("vec3", None)
    normal: tuple = param("vec3", None)
    center_m: tuple = param("vec3", None)
    radius_m: float = param("positive", None)
    lo_m: tuple = param("vec3", None)
    hi_m: tuple = param("vec3", None)

    def compile(self, b, what):
        idx = super().compile(b, what)
        kind, par = self._shape(what)
        claim_points(b.claims, idx, "keep_in", what)
        b.add_rows(shape_kind=[int(kind)], shape_par=[par])
        b.add_rows(kin_vert=idx, kin_shape=np.full(idx.size, len(b.rows["shape_kind"]) - 1))

    def _shape(self, what):
        if self.shape == "half_space":
            p = checks.vec3(f"{what}.point_m", self.point_m)
            n = np.asarray(checks.vec3(f"{what}.normal", self.normal))
            nn = np.linalg.norm(n)
            if nn == 0:
                raise SceneError(f"{what}.normal: expected a non-zero vector, received {self.normal!r}")
            return KeepInShape.HALF_SPACE, np.concatenate([p, n / nn])
        if self.shape == "ball":
            c = checks.vec3(f"{what}.center_m", self.center_m)
            r = checks.number(f"{what}.radius_m", self.radius_m, lo=0)
            return KeepInShape.BALL, np.array([*c, r, 0.0, 0.0])
        if self.shape == "box":
            lo, hi = checks.vec3(f"{what}.lo_m", self.lo_m), checks.vec3(f"{what}.hi_m", self.hi_m)
            if np.any(np.asarray(hi) <= np.asarray(lo)):
                raise SceneError(
                    f"{what}: expected lo_m < hi_m componentwise, received lo_m={self.lo_m!r} hi_m={self.hi_m!r}"
                )
            return KeepInShape.BOX, np.concatenate([lo, hi])
        raise SceneError(f"{what}.shape: expected 'half_space', 'ball' or 'box', received {self.shape!r}")


# ---------------------------------------------------------------- kernels


@kernel
def apply_prescribed(pre_vert, pre_rest, pre_sched, sched_next, h, vert_pos, vert_vel):
    """Prescribed trajectories: x_i(t+h) = rest_i + disp_s(t+h), v_i = dx / h.
    # Model: pre_vert (n,) int32, pre_rest (n, 3) m, pre_sched (n,) int64
    # Data in: sched_next (nsched, 3) m, schedules at t + h
    # Data out: vert_pos, vert_vel
    """
    for k in range(pre_vert.shape[0]):
        i = pre_vert[k]
        s = pre_sched[k]
        for a in range(3):
            x = pre_rest[k, a] + sched_next[s, a]
            vert_vel[i, a] = (x - vert_pos[i, a]) / h
            vert_pos[i, a] = x


@kernel
def apply_keep_in(kin_vert, kin_shape, shape_kind, shape_par, vert_pos, vert_vel):
    """Keep points inside a half-space, ball or box: project the position onto
    the region and remove the outward velocity component.
    # Model: kin_vert (n,) int32, kin_shape (n,) int64, shape_kind (ns,) int64,
    #        shape_par (ns, 6): half-space (point, unit normal pointing inside),
    #        ball (center, radius, -, -), box (lo, hi)
    # Data in/out: vert_pos, vert_vel
    """
    for k in range(kin_vert.shape[0]):
        i = kin_vert[k]
        s = kin_shape[k]
        par = shape_par[s]
        kind = shape_kind[s]
        if kind == KeepInShape.HALF_SPACE:
            d = (
                (vert_pos[i, 0] - par[0]) * par[3]
                + (vert_pos[i, 1] - par[1]) * par[4]
                + (vert_pos[i, 2] - par[2]) * par[5]
            )
            if d < 0.0:
                vn = vert_vel[i, 0] * par[3] + vert_vel[i, 1] * par[4] + vert_vel[i, 2] * par[5]
                for a in range(3):
                    vert_pos[i, a] -= d * par[3 + a]
                    if vn < 0.0:
                        vert_vel[i, a] -= vn * par[3 + a]
        elif kind == KeepInShape.BALL:
            dx, dy, dz = vert_pos[i, 0] - par[0], vert_pos[i, 1] - par[1], vert_pos[i, 2] - par[2]
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
            if r > par[3]:
                ux, uy, uz = dx / r, dy / r, dz / r
                vert_pos[i, 0] = par[0] + par[3] * ux
                vert_pos[i, 1] = par[1] + par[3] * uy
                vert_pos[i, 2] = par[2] + par[3] * uz
                vn = vert_vel[i, 0] * ux + vert_vel[i, 1] * uy + vert_vel[i, 2] * uz
                if vn > 0.0:
                    vert_vel[i, 0] -= vn * ux
                    vert_vel[i, 1] -= vn * uy
                    vert_vel[i, 2] -= vn * uz
        else:
            for a in range(3):
                if vert_pos[i, a] < par[a]:
                    vert_pos[i, a] = par[a]
                    if vert_vel[i, a] < 0.0:
                        vert_vel[i, a] = 0.0
                elif vert_pos[i, a] > par[3 + a]:
                    vert_pos[i, a] = par[3 + a]
                    if vert_vel[i, a] > 0.0:
                        vert_vel[i, a] = 0.0
