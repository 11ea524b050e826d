"""The inner envelope of a trunk skeleton in cylindrical coordinates about the cavity's axis.

The frame: cranial from the pelvis's centroid to the rib cage's, anterior from the spine's
centroid to the rib cage's (made perpendicular), each snapped to the model's nearest axis
when within `SNAP_DEG` (models are drawn axis-aligned; a direction from bone centroids is
off by a few degrees); left = cranial x anterior. The axis runs along cranial through the
mid-sagittal plane (the spine's mean left coordinate), halfway between the inner front of
the lower rib cage and the front of the spine there.

About it, column j holds azimuth 2 pi j / N from the anterior midline toward the left;
rows are `ROW_M` apart along cranial. A bone's surface, sampled finer than a row (its
faces split to `SAMPLE_M`), gives in each cell the least distance from the axis of any of
its points: the skeleton's inner face. The rib cage's envelope is filled across the
intercostal gaps (linear in height within a column), as the intercostal muscles close them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

__all__ = ["Envelope", "Frame", "envelope_of", "frame_of", "SNAP_DEG", "ROW_M", "SAMPLE_M"]

#: a direction within this of a model axis is taken as that axis (deg)
SNAP_DEG = 10.0
#: the envelope's row height (m)
ROW_M = 0.005
#: bone faces are split until no edge is longer (m), so that every cell sees their surface
SAMPLE_M = 0.004
#: the midline's half-width (m): bone points within it of the mid-sagittal plane are "on
#: the midline" (the sternum, the vertebral bodies, the sacrum, the pubic symphysis)
MIDLINE_M = 0.03
#: the least depth (m) between the sternum and the spine for a slab to place the axis
_MIN_DEPTH_M = 0.04


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _snap(v: np.ndarray) -> np.ndarray:
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) >= np.cos(np.radians(SNAP_DEG)):
        out = np.zeros(3)
        out[k] = np.sign(v[k])
        return out
    return v


@dataclass
class Frame:
    """The cavity's axis (`origin` (3,) m, on the axis at cranial coordinate 0) and the
    model's unit directions `cranial`, `anterior`, `left` (3,)."""

    origin: np.ndarray
    cranial: np.ndarray
    anterior: np.ndarray
    left: np.ndarray
    #: the axis's anterior shift (m) from `origin` at heights `shift_z` (m): it follows the
    #: rib cage's centre up the thorax (the upper chest lies behind the lower's centre)
    shift_z: np.ndarray = field(default_factory=lambda: np.zeros(1))
    shift_m: np.ndarray = field(default_factory=lambda: np.zeros(1))

    def axis(self, z) -> np.ndarray:
        """The axis's points (..., 3) at heights z (m)."""
        z = np.asarray(z, float)
        a = np.interp(z, self.shift_z, self.shift_m)
        return self.origin + z[..., None] * self.cranial + a[..., None] * self.anterior

    def cyl(self, p: np.ndarray) -> tuple:
        """(azimuth rad in [0, 2 pi) from anterior toward left, height m along cranial,
        distance m from the axis) of points p (n, 3)."""
        p = np.asarray(p, float)
        z = (p - self.origin) @ self.cranial
        d = p - self.axis(z)
        a, lf = d @ self.anterior, d @ self.left
        return np.mod(np.arctan2(lf, a), 2 * np.pi), z, np.hypot(a, lf)

    def point(self, phi, z, r) -> np.ndarray:
        """Points (..., 3) at azimuth phi (rad), height z (m), distance r (m) from the axis."""
        phi, z, r = np.broadcast_arrays(np.asarray(phi, float), np.asarray(z, float), np.asarray(r, float))
        radial = np.cos(phi)[..., None] * self.anterior + np.sin(phi)[..., None] * self.left
        return self.axis(z) + r[..., None] * radial


def dense_points(bones) -> np.ndarray:
    """The bones' surfaces as points no further than `SAMPLE_M` apart along their edges."""
    parts = []
    for b in bones:
        v, f = trimesh.remesh.subdivide_to_size(b.vert, b.face, max_edge=SAMPLE_M, max_iter=20)
        parts.append(np.asarray(v))
    return np.concatenate(parts) if parts else np.zeros((0, 3))


def frame_of(rib: np.ndarray, spine: np.ndarray, pelvis: np.ndarray) -> Frame:
    """The cavity's `Frame` from the roles' points (module docstring)."""
    cranial = _snap(_unit(rib.mean(axis=0) - pelvis.mean(axis=0)))
    z_rib = rib @ cranial
    low = spine[(spine @ cranial >= z_rib.min()) & (spine @ cranial <= np.percentile(z_rib, 50))]
    fwd = rib.mean(axis=0) - (low if len(low) else spine).mean(axis=0)
    anterior = _snap(_unit(fwd - (fwd @ cranial) * cranial))
    anterior = _unit(anterior - (anterior @ cranial) * cranial)
    left = np.cross(cranial, anterior)
    mid = float(np.median(spine @ left))
    # the lower rib cage, from its lowest point up 40% of its height: its front near the
    # midline (the xiphoid and the costal cartilages)
    z0, z1 = z_rib.min(), z_rib.min() + 0.4 * np.ptp(z_rib)
    slab = rib[(z_rib <= z1) & (np.abs(rib @ left - mid) < MIDLINE_M)]
    if not len(slab):
        slab = rib[z_rib <= z1]
    front = float(np.percentile(slab @ anterior, 95))
    zs = spine @ cranial
    sp = spine[(zs >= z0) & (zs <= z1) & (np.abs(spine @ left - mid) < MIDLINE_M)]
    back = float(np.max((sp if len(sp) else spine) @ anterior))
    origin = mid * left + 0.5 * (front + back) * anterior
    # up the thorax, the centre between the midline's front (sternum) and the spine's front,
    # 1 cm slabs, where the two are more than `_MIN_DEPTH_M` apart (below the xiphoid the
    # midline holds no front: the lower value holds)
    zs_rib = rib @ cranial
    near_rib = np.abs(rib @ left - mid) < MIDLINE_M
    near_sp = np.abs(spine @ left - mid) < MIDLINE_M
    hz, hm = [float(z0)], [0.0]
    for zc in np.arange(z1, zs_rib.max(), 0.01):
        fr_ = rib[near_rib & (np.abs(zs_rib - zc) < 0.015)] @ anterior
        bk_ = spine[near_sp & (np.abs(zs - zc) < 0.015)] @ anterior
        if len(fr_) and len(bk_) and np.percentile(fr_, 95) - bk_.max() > _MIN_DEPTH_M:
            hz.append(float(zc))
            hm.append(0.5 * (float(np.percentile(fr_, 95)) + float(bk_.max())) - 0.5 * (front + back))
    return Frame(
        origin=origin, cranial=cranial, anterior=anterior, left=left, shift_z=np.array(hz), shift_m=np.array(hm)
    )


@dataclass
class Envelope:
    """Per column and row the least distance (m) of a role's bone from the axis (NaN where
    none lies): `rib` (filled across the gaps, `module docstring`), `bone` (every role),
    `spine`; `z0` the first row's height, `rib_low` and `rib_top` each column's lowest and
    highest rib point (m)."""

    frame: Frame
    columns: int
    z0: float
    rib: np.ndarray
    bone: np.ndarray
    spine: np.ndarray
    rib_low: np.ndarray
    rib_top: np.ndarray

    def phi(self) -> np.ndarray:
        return 2 * np.pi * np.arange(self.columns) / self.columns

    def _at(self, grid: np.ndarray, j: int, z) -> np.ndarray:
        zq = np.atleast_1d(np.asarray(z, float))
        k = np.clip(np.round((zq - self.z0) / ROW_M).astype(int), 0, grid.shape[1] - 1)
        # the least over the neighbouring rows and columns: the surface between the mesh's
        # points stays inside what the points see
        js = [(j - 1) % self.columns, j, (j + 1) % self.columns]
        out = np.full(len(zq), np.inf)
        for dk in (-1, 0, 1):
            kk = np.clip(k + dk, 0, grid.shape[1] - 1)
            vals = grid[np.ix_(js, kk)]
            vals = np.where(np.isnan(vals), np.inf, vals).min(axis=0)
            out = np.minimum(out, vals)
        return out

    def rib_at(self, j: int, z) -> np.ndarray:
        return self._at(self.rib, j, z)

    def bone_at(self, j: int, z) -> np.ndarray:
        return np.minimum(self._at(self.bone, j, z), self._at(self.rib, j, z))

    def spine_at(self, j: int, z) -> np.ndarray:
        return self._at(self.spine, j, z)


def _grid(frame: Frame, pts: np.ndarray, columns: int, z0: float, rows: int) -> np.ndarray:
    phi, z, r = frame.cyl(pts)
    j = np.round(phi / (2 * np.pi / columns)).astype(int) % columns
    k = np.round((z - z0) / ROW_M).astype(int)
    ok = (k >= 0) & (k < rows)
    g = np.full(columns * rows, np.inf)
    np.minimum.at(g, j[ok] * rows + k[ok], r[ok])
    g[np.isinf(g)] = np.nan
    return g.reshape(columns, rows)


def envelope_of(frame: Frame, rib: np.ndarray, spine: np.ndarray, pelvis: np.ndarray, columns: int) -> Envelope:
    """The `Envelope` of the roles' points (dense, `dense_points`) about `frame`'s axis."""
    allz = np.concatenate([rib, spine, pelvis]) @ frame.cranial
    z0 = float(allz.min()) - ROW_M
    rows = int(np.ceil((allz.max() - z0) / ROW_M)) + 2
    g_rib = _grid(frame, rib, columns, z0, rows)
    phi, z, _ = frame.cyl(rib)
    j = np.round(phi / (2 * np.pi / columns)).astype(int) % columns
    low = np.full(columns, np.nan)
    top = np.full(columns, np.nan)
    for c in range(columns):
        zc = z[j == c]
        if len(zc):
            low[c], top[c] = zc.min(), zc.max()
    filled = g_rib.copy()
    zk = z0 + ROW_M * np.arange(rows)
    for c in range(columns):
        have = ~np.isnan(g_rib[c])
        if have.sum() >= 2:
            inside = (zk >= zk[have].min()) & (zk <= zk[have].max())
            filled[c, inside] = np.interp(zk[inside], zk[have], g_rib[c, have])
    bone = _grid(frame, np.concatenate([spine, pelvis]), columns, z0, rows)
    return Envelope(
        frame=frame,
        columns=columns,
        z0=z0,
        rib=filled,
        bone=bone,
        spine=_grid(frame, spine, columns, z0, rows),
        rib_low=low,
        rib_top=top,
    )
