"""Local shape memory (paper 3.4): each point attracted to its ideal place in
the frame of its neighbour ring, F_i = k_i (P_ideal - P_i).

The frame is built from the ring N_1..N_eta only (G their mean, n the normalised
sum of (N_j - G) x (N_j+1 - G), t1 the tangential part of N_1 - G, t2 = n x t1),
so the force vanishes at rest and turns with any rigid motion of the surface. It
has no reaction on the neighbours: the force is not conservative (with too little
damping it excites itself, as `hybrid study stability` measures). Rest data: each
point's (alpha, beta, gamma) in its rest frame (`shape_memory_frame_coef`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from .. import checks
from ..errors import MeshError
from ..kernel import kernel, kernel_twin
from .base import Rows, Term, force, param

__all__ = [
    "ShapeMemory",
    "ring_frame",
    "shape_memory_frame_coef",
    "shape_memory_frames",
    "shape_memory_frames_parallel",
    "shape_memory_force",
    "add_shape_memory",
    "add_shape_memory_parallel",
]


@force("shape_memory")
class ShapeMemory(Term):
    """Local shape memory (paper 3.4): each point attracted to its ideal place
    in the frame of its neighbours, stiffness in N/m."""

    formulations = ("paper",)  # a per-point parameter: its meaning changes with the mesh
    # sm_vert (nsm,) int32 sorted; sm_stiff (nsm,) N/m; sm_coef (nsm, 3) m
    arrays = {"sm_vert": Rows(np.int32), "sm_stiff": Rows(float), "sm_coef": Rows(float, 3)}
    stiffness_n_per_m: float = param("positive", hi=checks.MAX_STIFFNESS_N_PER_M)
    region: object = param("selector", "all")

    def compile(self, b, what):
        idx = super().compile(b, what)
        b.rows["shape_memory"].append((idx, self.value("stiffness_n_per_m", what)))

    @classmethod
    def finish(cls, b):
        stiff = np.zeros(b.mesh.nvert)
        for idx, k in b.rows["shape_memory"]:
            stiff[idx] = k  # a later term wins where regions overlap
        sm_vert = np.nonzero((stiff > 0) & b.moving)[0].astype(np.int32)
        mesh = b.mesh
        b.out["sm_vert"] = sm_vert
        b.out["sm_stiff"] = stiff[sm_vert].copy()
        b.out["sm_coef"] = (
            np.ascontiguousarray(
                shape_memory_frame_coef(mesh.vert_pos, mesh.ring_ptr, mesh.ring_vert, mesh.ring_closed, sm_vert)
            )
            if sm_vert.size
            else np.zeros((0, 3))
        )
        b.vert_stiffness += stiff


# ---------------------------------------------------------------- the local frame


@kernel(inline="always")
def ring_sums(vert_pos, ring_ptr, ring_vert, ring_closed, i):
    """First half of the local frame of vertex i (module docstring), one pass over its ring:
    G, the mean of the neighbours N_1..N_eta (m), the unnormalised normal,
    the sum of (N_j - G) x (N_j+1 - G) over the fan's consecutive pairs (m^2),
    and N_1 - G (m), which the second half needs.
    The cross sum is taken relative to N_1 and moved to G afterwards (for a
    closed fan it does not depend on the origin; for an open one it changes by
    (N_eta - N_1) x (G - N_1)). Returns (Gx, Gy, Gz, nx, ny, nz, dx, dy, dz).
    # Model: ring_ptr, ring_vert, ring_closed   # Data in: vert_pos (nvert, 3) m, i
    # Data out: returns the 9 floats above
    """
    # unsigned indices: numba then skips its negative-index wraparound, a
    # fifth of the instructions of each neighbour
    i = np.uint64(i)
    b, e = np.uint64(ring_ptr[i]), np.uint64(ring_ptr[i + np.uint64(1)])
    v = np.uint64(ring_vert[b])
    x1, y1, z1 = vert_pos[v, 0], vert_pos[v, 1], vert_pos[v, 2]
    sx = sy = sz = 0.0  # sum of N_j - N_1
    nx = ny = nz = 0.0
    ax = ay = az = 0.0  # previous N_j - N_1 (zero for j = 1)
    for j in range(b + np.uint64(1), e):
        v = np.uint64(ring_vert[j])
        bx, by, bz = vert_pos[v, 0] - x1, vert_pos[v, 1] - y1, vert_pos[v, 2] - z1
        sx += bx
        sy += by
        sz += bz
        nx += ay * bz - az * by
        ny += az * bx - ax * bz
        nz += ax * by - ay * bx
        ax, ay, az = bx, by, bz
    inv = 1.0 / float(e - b)
    gx, gy, gz = sx * inv, sy * inv, sz * inv  # G - N_1
    if not ring_closed[i]:
        nx += ay * gz - az * gy
        ny += az * gx - ax * gz
        nz += ax * gy - ay * gx
    gx += x1
    gy += y1
    gz += z1
    return gx, gy, gz, nx, ny, nz, x1 - gx, y1 - gy, z1 - gz


@kernel(inline="always")
def frame_axes(dx, dy, dz, nx, ny, nz):
    """Second half: unit n, t1 = unit tangential part of d = N_1 - G, t2 = n x t1,
    from `ring_sums`. Returns (t1, t2, n) as 9 floats.
    # Model: none   # Data in: d = N_1 - G (m), n (unnormalised)   # Data out: returns (t1, t2, n)
    """
    r = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    nx *= r
    ny *= r
    nz *= r
    dn = dx * nx + dy * ny + dz * nz
    tx, ty, tz = dx - dn * nx, dy - dn * ny, dz - dn * nz
    r = 1.0 / math.sqrt(tx * tx + ty * ty + tz * tz)
    tx *= r
    ty *= r
    tz *= r
    return tx, ty, tz, ny * tz - nz * ty, nz * tx - nx * tz, nx * ty - ny * tx, nx, ny, nz


@kernel
def ring_frame(vert_pos, ring_ptr, ring_vert, ring_closed, i):
    """The local frame of vertex i from its neighbour ring only: (G, t1, t2, n)
    as 12 floats and |cross sum| (m^2), 0 when the frame is degenerate.
    # Model: ring_ptr, ring_vert, ring_closed   # Data in: vert_pos (nvert, 3) m, i
    # Data out: returns (G, t1, t2, n, |cross sum|)
    """
    gx, gy, gz, nx, ny, nz, dx, dy, dz = ring_sums(vert_pos, ring_ptr, ring_vert, ring_closed, i)
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    tx, ty, tz, ux, uy, uz, nx, ny, nz = frame_axes(dx, dy, dz, nx, ny, nz)
    return gx, gy, gz, tx, ty, tz, ux, uy, uz, nx, ny, nz, nn


def shape_memory_frame_coef(vert_pos, ring_ptr, ring_vert, ring_closed, verts) -> np.ndarray:
    """(alpha, beta, gamma) (m) of each vertex in `verts` in its rest ring frame.

    Returns (len(verts), 3). Raises MeshError naming vertices whose ring
    frame is degenerate (fewer than 3 neighbours, or all on one line).
    """
    coef = np.zeros((len(verts), 3))
    bad = []
    for k, i in enumerate(verts):
        if ring_ptr[i + 1] - ring_ptr[i] < 2:
            bad.append(int(i))
            continue
        f = ring_frame(vert_pos, ring_ptr, ring_vert, ring_closed, i)
        scale = float(np.ptp(vert_pos[ring_vert[ring_ptr[i] : ring_ptr[i + 1]]], axis=0).max())
        if not (f[12] > 1e-10 * scale * scale) or not np.all(np.isfinite(f[:12])):
            bad.append(int(i))
            continue
        d = vert_pos[i] - np.array(f[0:3])
        coef[k] = (np.dot(f[3:6], d), np.dot(f[6:9], d), np.dot(f[9:12], d))
    if bad:
        raise MeshError(
            f"shape memory: vertices {bad[:8]} ({len(bad)} in all) have a degenerate neighbour "
            f"ring (expected at least 3 neighbours not all on one line); leave them out of the "
            f"shape-memory region or nail them"
        )
    return coef


# ---------------------------------------------------------------- kernels


@kernel(inline="always")
def _store_ring_sums(sm_vert, ring_ptr, ring_vert, ring_closed, vert_pos, sm_sums, k):
    """Row k of sm_sums: `ring_sums` of shape-memory point sm_vert[k].
    # Model: sm_vert (nsm,) int32, ring_ptr, ring_vert, ring_closed   # Data in: vert_pos m, k
    # Data out: sm_sums[k] (9 floats)
    """
    gx, gy, gz, nx, ny, nz, dx, dy, dz = ring_sums(vert_pos, ring_ptr, ring_vert, ring_closed, sm_vert[k])
    sm_sums[k, 0] = gx
    sm_sums[k, 1] = gy
    sm_sums[k, 2] = gz
    sm_sums[k, 3] = nx
    sm_sums[k, 4] = ny
    sm_sums[k, 5] = nz
    sm_sums[k, 6] = dx
    sm_sums[k, 7] = dy
    sm_sums[k, 8] = dz


def _shape_memory_frames(sm_vert, ring_ptr, ring_vert, ring_closed, vert_pos, sm_sums):
    """First pass of the local shape memory: the ring gathers of `ring_sums`,
    G, the unnormalised normal and N_1 - G, into sm_sums (n, 9). The second
    pass (`shape_memory_force`) normalises them: kept apart, the gathers do
    not stall on the dependent square roots and divisions of each point.
    # Model: sm_vert (n,) int32, ring_*   # Data in: vert_pos (nvert, 3) m
    # Data out: sm_sums (n, 9) m, m^2, m
    """
    for k in prange(sm_vert.shape[0]):
        _store_ring_sums(sm_vert, ring_ptr, ring_vert, ring_closed, vert_pos, sm_sums, k)


shape_memory_frames, shape_memory_frames_parallel = kernel_twin(_shape_memory_frames)


@kernel(inline="always")
def shape_memory_force(sm_stiff, sm_coef, sm_sums, k, px, py, pz):
    """Second pass, one point: k (P_ideal - P) (N) for shape-memory point k at P (m),
    P_ideal = G + alpha t1 + beta t2 + gamma n from its `shape_memory_frames` row.
    # Model: sm_stiff (nsm,) N/m, sm_coef (nsm, 3) m (alpha, beta, gamma)
    # Data in: sm_sums (the frames' rows), k, P = (px, py, pz) m   # Data out: returns the force N
    """
    gx, gy, gz = sm_sums[k, 0], sm_sums[k, 1], sm_sums[k, 2]
    tx, ty, tz, ux, uy, uz, nx, ny, nz = frame_axes(
        sm_sums[k, 6], sm_sums[k, 7], sm_sums[k, 8], sm_sums[k, 3], sm_sums[k, 4], sm_sums[k, 5]
    )
    al, be, ga = sm_coef[k, 0], sm_coef[k, 1], sm_coef[k, 2]
    c = sm_stiff[k]
    return (
        c * (gx + al * tx + be * ux + ga * nx - px),
        c * (gy + al * ty + be * uy + ga * ny - py),
        c * (gz + al * tz + be * uz + ga * nz - pz),
    )


def _add_shape_memory(sm_vert, sm_stiff, sm_coef, ring_ptr, ring_vert, ring_closed, vert_pos, sm_sums, vert_force):
    """Local shape memory (paper 3.4): F_i += k_i (P_ideal - P_i).

    P_ideal = G + alpha t1 + beta t2 + gamma n in the frame of the current
    neighbour ring (`ring_frame`), so the force vanishes at rest and turns
    with any rigid motion of the surface. No reaction on the neighbours: the
    force is not conservative. Two passes, the ring gathers then the
    normalisations (`shape_memory_frames`, `shape_memory_force`); the step
    fuses the second pass with its other per-point work (hybrid.terms.pointwise).
    # Model: sm_vert (n,) int32, sm_stiff (n,) N/m, sm_coef (n, 3) m, ring_*
    # Data in: vert_pos (nvert, 3) m
    # Scratch: sm_sums (n, 9)
    # Data out: vert_force
    Compiled twice (hybrid.kernel): `add_shape_memory` and `add_shape_memory_parallel`.
    """
    for k in prange(sm_vert.shape[0]):
        _store_ring_sums(sm_vert, ring_ptr, ring_vert, ring_closed, vert_pos, sm_sums, k)
    for k in prange(sm_vert.shape[0]):
        i = np.uint64(sm_vert[k])
        fx, fy, fz = shape_memory_force(sm_stiff, sm_coef, sm_sums, k, vert_pos[i, 0], vert_pos[i, 1], vert_pos[i, 2])
        vert_force[i, 0] += fx
        vert_force[i, 1] += fy
        vert_force[i, 2] += fz


add_shape_memory, add_shape_memory_parallel = kernel_twin(_add_shape_memory)
