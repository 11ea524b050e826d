"""The abdomen-diaphragm surface and the thoracic cavity lofted in a skeleton's `Envelope`.

Every column of points (an azimuth about the cavity's axis) is one meridian, from the pelvic
floor's lowest point up to the dome's apex, through the same stations on every column:

- the pelvic floor: a quarter ellipse from the floor's lowest point (the coccyx's level) up
  to the pelvic inlet (the sacral promontory's height);
- the abdominal wall: from the inlet up to the costal margin (each column's lowest rib
  point) at the margin's distance from the axis, bulging `WALL_BULGE` halfway (the wall holds
  no bone to follow), leaving the top of a bone that held it in (the iliac crest, the
  sacral promontory) at no more than `SHELF_SLOPE` outward per height;
- the zone of apposition: up the rib cage's inner face from the costal margin, over the
  same fraction of each column's rib cage height; the fraction is solved for so that the
  zone covers `zoa_area_share` of the rib cage's inner surface (Mead 1979, Am Rev Respir
  Dis 119:31: a quarter to a third of it during quiet breathing upright);
- the dome: rings shrinking, as a quarter ellipse, from the zone's top toward the apex
  over the centre of the zone's top ring, `dome_rise_m` above the zone's highest point,
  rounding toward circles as they rise (`DOME_ROUND_POWER`), each point drawn in under the
  thoracic cavity's wall.

Each point below the dome keeps `clearance_m` inside the skeleton's inner face wherever a
bone lies in its cell (the spine, the sacrum and the pelvis as well as the ribs). A point's
height along its meridian only increases and, below the dome, its meridian lies in its own
half-plane about the axis; near the poles every other column is dropped where the rings
close in, and the floor's and the dome's rings lose points where they run close to the axis
(`_thin`). Where a ring steps round a vertebral body its long edge is split by points on it
(`_split_long`), and rings of any counts are stitched by their nearest points (`_stitch`):
the triangles stay near equilateral (quality 0.37 at worst on myo-sim's torso, 0.06 with
one edge across each step). `hybrid.anatomy.fit` checks the result: closed, oriented, no
two triangles crossing (`hybrid.mesh.intersect`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybrid.errors import MeshError

from .envelope import ROW_M, Envelope

__all__ = ["Loft", "loft", "thoracic_cavity_surface"]

#: the least distance (m) of a point from the axis (a bone nearer the axis than this plus
#: the clearance would leave no room)
_MIN_R_M = 0.002
#: the abdominal wall's outward bulge halfway between the inlet and the costal margin, a
#: fraction of the margin's distance from the axis (an assumption: the wall is convex
#: in front; it also keeps the wall's triangles out of one plane)
WALL_BULGE = 0.1
#: the dome's least distance inside the room its ring's azimuth leaves (m)
_DOME_GAP_M = 0.001
#: the thoracic cavity's top plane under the rib cage's lowest top (m)
TOP_MARGIN_M = 0.02
#: a ring's edge longer than this many of the loft's spacings is split (`_split_long`)
LONG_EDGE = 2.0
#: how far (m) a point dropped from a ring (`_thin`) may lie off the edge that replaces it
THIN_SAG_M = 0.001
#: the steepest outward slope (m per m of height) of the abdominal wall above the top edge
#: of a bone that held the ring below it in (`loft`)
SHELF_SLOPE = 2.0
#: a ring's point nearer than this (m) to its clearance inside a vertebra is held by the spine
_SPINE_TOL_M = 0.001
#: a dome ring is drawn toward the circle of its points' mean distance from the dome's
#: centre line by its rise fraction to this power: the notch the zone's top ring makes round
#: the vertebral bodies fades out toward the apex, where scaled copies of it crowded the
#: rings' points together behind the centre line
DOME_ROUND_POWER = 4


def _periodic_fill(v: np.ndarray) -> np.ndarray:
    """NaNs of a periodic column series filled linearly from their neighbours."""
    n = len(v)
    have = ~np.isnan(v)
    if not have.any():
        raise MeshError("expected a rib cage around the cavity's axis, received no rib point in any column")
    x = np.arange(n)
    xs = np.concatenate([x[have] - n, x[have], x[have] + n])
    return np.interp(x, xs, np.tile(v[have], 3))


def _smooth(v: np.ndarray) -> np.ndarray:
    return (np.roll(v, 1) + v + np.roll(v, -1)) / 3.0


@dataclass
class Loft:
    """The closed surface: points `vert` (n, 3) m and outward triangles `face` (m, 3);
    `rings` the point indices of each ring from bottom to top (poles apart), `kind` each
    ring's part ("floor", "wall", "zoa", "dome"), `dome_rise` each dome ring's fraction of
    the dome's height; `bottom` and `apex` the poles' indices; the stations: `z_cm`,
    `z_top`, `r_top` per column (m), `z_in`, `z_floor`, `z_apex` (m); `zoa_fraction` of each
    column's rib cage height and `zoa_area_share` of the rib cage's inner surface."""

    vert: np.ndarray
    face: np.ndarray
    rings: list
    kind: list
    dome_rise: list
    bottom: int
    apex: int
    z_cm: np.ndarray
    z_top: np.ndarray
    r_top: np.ndarray
    z_rib_top: np.ndarray
    z_in: float
    z_floor: float
    z_apex: float
    zoa_fraction: float
    zoa_area_share: float
    columns: int = 0
    extra: dict = field(default_factory=dict)

    def points_of(self, kinds) -> np.ndarray:
        return np.concatenate([r for r, k in zip(self.rings, self.kind) if k in kinds]).astype(np.int64)


def _band_area(env: Envelope, phi, z_lo, z_hi, radius, rows: int = 16) -> float:
    """The area (m^2) of the band between heights z_lo and z_hi (per column) at the
    distances radius(j, z) from the axis."""
    zs = z_lo[:, None] + (z_hi - z_lo)[:, None] * np.linspace(0.0, 1.0, rows)[None, :]
    pts = np.stack([env.frame.point(phi[j], zs[j], radius(j, zs[j])) for j in range(len(phi))])
    a, b = pts, np.roll(pts, -1, axis=0)
    c, d = a[:, 1:], b[:, 1:]
    a, b = a[:, :-1], b[:, :-1]
    t1 = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=-1)
    t2 = 0.5 * np.linalg.norm(np.cross(d - b, c - b), axis=-1)
    return float(t1.sum() + t2.sum())


def loft(
    env: Envelope,
    z_in: float,
    z_floor: float,
    *,
    clearance_m: float,
    zoa_area_share: float,
    dome_rise_m: float,
    edge_m: float | None = None,
) -> Loft:
    """The closed surface (module docstring) in the envelope `env`; the pelvic inlet at
    height z_in and the floor's lowest point at z_floor (m along the frame's cranial)."""
    n = env.columns
    phi = env.phi()
    spine_cols = spine_columns(env, z_in, float(np.nanmin(env.rib_low)))
    low, top = env.rib_low.copy(), env.rib_top.copy()
    # at the spine the rib cage's own lowest point is no margin (the ribs' heads): the
    # margin's neighbours carry across it, as the crura do
    low[spine_cols], top[spine_cols] = np.nan, np.nan
    z_cm = _smooth(_periodic_fill(low))
    z_rt = _smooth(_periodic_fill(top))
    if not z_in < z_cm.min():
        raise MeshError(
            f"expected the pelvic inlet below the costal margin, received the inlet at {z_in:.4g} m and the "
            f"margin's lowest point at {z_cm.min():.4g} m along the model's cranial direction"
        )

    def inner(j, z):  # the distance (m) a point keeps from the axis at (column j, height z)
        return np.maximum(np.minimum(env.rib_at(j, z), env.bone_at(j, z)) - clearance_m, _MIN_R_M)

    r_cm = np.array([float(inner(j, z_cm[j])[0]) for j in range(n)])
    r_cm = np.where(np.isfinite(r_cm), r_cm, np.nan)
    r_cm = _periodic_fill(r_cm)

    def wall(j, z):  # the abdominal wall's bulge: `WALL_BULGE` of its radius halfway up
        s = np.clip((np.asarray(z, float) - z_in) / (z_cm[j] - z_in), 0.0, 1.0)
        r = r_cm[j] * (1.0 + WALL_BULGE * np.sin(np.pi * s))
        return np.maximum(np.minimum(r, env.bone_at(j, z) - clearance_m), _MIN_R_M)

    whole = _band_area(env, phi, z_cm, z_rt, inner)
    lo, hi = 0.0, 1.0
    for _ in range(30):  # the zone's fraction of each column's rib cage height, by bisection
        mid = 0.5 * (lo + hi)
        share = _band_area(env, phi, z_cm, z_cm + mid * (z_rt - z_cm), inner) / whole
        lo, hi = (mid, hi) if share < zoa_area_share else (lo, mid)
    f = 0.5 * (lo + hi)
    z_top = z_cm + f * (z_rt - z_cm)
    share = _band_area(env, phi, z_cm, z_top, inner) / whole
    r_top = np.array([float(inner(j, z_top[j])[0]) for j in range(n)])
    z_apex = float(z_top.max()) + dome_rise_m
    # the thoracic cavity's wall up the rib cage from the zone's top to one top plane,
    # `TOP_MARGIN_M` under the lowest column's top (the manubrium's): the first ribs close in
    # over the apices too fast for rings about one axis to follow
    z_hi = float(z_rt.min()) - TOP_MARGIN_M
    if not z_hi > z_apex:
        raise MeshError(
            f"expected the rib cage's top above the dome's apex ({z_apex:.4g} m), received a column topping out at "
            f"{z_hi + TOP_MARGIN_M:.4g} m"
        )
    n_up = max(3, int(np.ceil(float(np.mean(z_hi - z_top)) / (2 * np.pi * float(r_top.mean()) / n))))
    wall_z = z_top[None, :] + (z_hi - z_top)[None, :] * (np.arange(n_up + 1) / n_up)[:, None]
    wall_r = np.array([[float(inner(j, wall_z[k, j])[0]) for j in range(n)] for k in range(n_up + 1)])
    wall_r[0] = r_top
    r_in = np.array([float(wall(j, z_in)[0]) for j in range(n)])

    h = float(edge_m) if edge_m else 2 * np.pi * float(r_cm.mean()) / n
    depth = z_in - z_floor
    n_floor = max(2, int(np.ceil(0.5 * np.pi * np.sqrt(0.5 * (depth**2 + r_in.mean() ** 2)) / h)))
    n_wall = max(2, int(np.ceil(float(np.mean(z_cm - z_in)) / h)))
    n_zoa = max(2, int(np.ceil(float(np.mean(z_top - z_cm)) / h)))
    rise = z_apex - z_top
    n_dome = max(3, int(np.ceil(0.5 * np.pi * np.sqrt(0.5 * (float(np.mean(rise)) ** 2 + r_top.mean() ** 2)) / h)))

    stations: list = []  # (kind, dome fraction, z(j), r(j)) per ring
    for i in range(1, n_floor + 1):
        s = i / n_floor
        zf = np.full(n, z_floor + depth * (1.0 - np.cos(0.5 * np.pi * s)))
        rf = np.array([min(r_in[j] * np.sin(0.5 * np.pi * s), float(wall(j, zf[j])[0])) for j in range(n)])
        stations.append(("floor", 0.0, zf, rf))
    for i in range(1, n_wall + 1):
        zw = z_in + (z_cm - z_in) * i / n_wall
        rw = np.array([float(wall(j, zw[j])[0]) for j in range(n)])
        # above the top edge of a bone that held the ring below in (the iliac crest, the
        # sacral promontory) the wall leaves it at no more than `SHELF_SLOPE` outward per
        # height: straight out, the step (40 mm over one ring on myo-sim's hip bones) gave
        # slivers. Not at the vertebral bodies: their sides are steps round every ring
        # (`_split_long`), and the gutters beside them hold much of the abdomen's volume
        _, _, zb, rb = stations[-1]
        free = np.array([float(env.spine_at(j, zb[j])[0]) - clearance_m > rb[j] + _SPINE_TOL_M for j in range(n)])
        rw = np.where(free, np.minimum(rw, rb + SHELF_SLOPE * (zw - zb)), rw)
        stations.append(("wall", 0.0, zw, rw))
    for i in range(1, n_zoa + 1):
        zz = z_cm + (z_top - z_cm) * i / n_zoa
        stations.append(("zoa", 0.0, zz, np.array([float(inner(j, zz[j])[0]) for j in range(n)])))
    # the inlet ring is the floor's last; the costal margin ring the wall's last
    pts = [env.frame.point(phi, z, r) for _, _, z, r in stations]
    # the dome's rings shrink toward the apex over the centre of the zone's top ring (in
    # front of the spine, behind the sternum), not toward the axis
    fr = env.frame
    top_ring = pts[-1]
    centre = top_ring.mean(axis=0)
    centre = centre - ((centre - fr.origin) @ fr.cranial) * fr.cranial
    for i in range(1, n_dome):
        t = i / n_dome
        zd = z_top + rise * np.sin(0.5 * np.pi * t)
        flat = top_ring - ((top_ring - fr.origin) @ fr.cranial)[:, None] * fr.cranial
        rel = flat - centre
        rho = np.maximum(np.linalg.norm(rel, axis=1), 1e-9)
        w = np.sin(0.5 * np.pi * t) ** DOME_ROUND_POWER  # its rise fraction's power
        rel = rel * ((1.0 - w) + w * float(rho.mean()) / rho)[:, None]
        ring = centre + np.cos(0.5 * np.pi * t) * rel + (zd - fr.origin @ fr.cranial)[:, None] * fr.cranial
        ring = _inside(env, wall_z, wall_r, ring, centre, zd)
        stations.append(("dome", float(np.sin(0.5 * np.pi * t)), zd, None))
        pts.append(ring)
    nring = len(pts)
    # near the poles every other column is dropped where a ring's spacing falls under half
    # the meridian's (edges far shorter than the rest would set the stable step)
    cols = [_ring_columns(n, float(np.mean(np.linalg.norm(np.diff(p, axis=0), axis=1))), h) for p in pts]
    for k in range(1, nring):  # at most halving from one ring to the next
        cols[k] = cols[k] if len(cols[k]) >= len(cols[k - 1]) // 2 else _every(n, len(cols[k - 1]) // 2)
    for k in range(nring - 2, -1, -1):
        cols[k] = cols[k] if len(cols[k]) >= len(cols[k + 1]) // 2 else _every(n, len(cols[k + 1]) // 2)
    bottom_pt = env.frame.point(0.0, z_floor, 0.0)
    apex_pt = centre + (z_apex - fr.origin @ fr.cranial) * fr.cranial
    # each column's spacing between rings (the meridian's), per ring
    below = [np.broadcast_to(bottom_pt, pts[0].shape), *pts[:-1]]
    above = [*pts[1:], np.broadcast_to(apex_pt, pts[-1].shape)]
    merid = [
        0.5 * (np.linalg.norm(p - b, axis=1) + np.linalg.norm(a - p, axis=1)) for p, b, a in zip(pts, below, above)
    ]
    # the floor's and the dome's rings thinned where they run close to the axis; the wall's
    # and the zone's keep every column (the spine's strip and the ribs' sectors are columns);
    # every ring's long edges split; rings of any counts stitched by their nearest points
    ring_u, ring_p = [], []
    for k in range(nring):
        c = cols[k]
        if stations[k][0] in ("floor", "dome"):
            c = _thin(pts[k], c, merid[k])
        u, p = _split_long(pts[k], c, n, h)
        ring_u.append(u)
        ring_p.append(p)
    vert = np.concatenate([bottom_pt[None], *ring_p, apex_pt[None]])
    start = np.cumsum([1] + [len(u) for u in ring_u])
    rings = [start[k] + np.arange(len(ring_u[k])) for k in range(nring)]
    bottom, apex = 0, int(start[-1])
    face = np.concatenate(
        [_fan(bottom, rings[0], up=False)]
        + [_stitch(rings[k], rings[k + 1], vert) for k in range(nring - 1)]
        + [_fan(apex, rings[-1], up=True)]
    )
    if _signed_volume(vert, face) < 0:
        face = face[:, [0, 2, 1]]
    return Loft(
        vert=vert,
        face=face,
        rings=rings,
        kind=[s[0] for s in stations],
        dome_rise=[s[1] for s in stations],
        bottom=bottom,
        apex=apex,
        z_cm=z_cm,
        z_top=z_top,
        r_top=r_top,
        z_rib_top=z_rt,
        z_in=z_in,
        z_floor=z_floor,
        z_apex=z_apex,
        zoa_fraction=f,
        zoa_area_share=share,
        columns=n,
        extra={
            "ring_columns": ring_u,
            "wall_z": wall_z,
            "wall_r": wall_r,
            "inner": inner,
            "spine_columns": spine_cols,
            "rings_per_part": {"floor": n_floor, "wall": n_wall, "zoa": n_zoa, "dome": n_dome},
        },
    )


def _inside(env: Envelope, wall_z, wall_r, ring: np.ndarray, centre: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The dome's ring with each point drawn toward the dome's centre line until it is
    `_DOME_GAP_M` inside the thoracic wall (its rings `wall_z`, `wall_r` per column, linear
    between them) at its own azimuth: the sternum slopes back above the xiphoid faster than
    the dome's front falls away."""
    fr = env.frame
    out = ring.copy()
    step = 2 * np.pi / env.columns
    for i, p in enumerate(ring):
        axis_c = centre + (z[i] - centre @ fr.cranial) * fr.cranial
        for shrink in np.linspace(1.0, 0.0, 81):
            q = axis_c + shrink * (p - axis_c)
            phi, zq, r = fr.cyl(q[None])
            j0 = int(np.floor(phi[0] / step)) % env.columns
            room = min(float(np.interp(zq[0], wall_z[:, j], wall_r[:, j])) for j in (j0, (j0 + 1) % env.columns))
            if r[0] <= room - _DOME_GAP_M:
                out[i] = q
                break
        else:
            out[i] = axis_c
    return out


def spine_columns(env: Envelope, z_lo: float, z_hi: float) -> np.ndarray:
    """The columns in which a vertebra lies in most rows between heights z_lo and z_hi (m):
    where the spine, not the ribs, is the cavity's back."""
    k0 = int(np.clip(np.round((z_lo - env.z0) / ROW_M), 0, env.spine.shape[1] - 1))
    k1 = int(np.clip(np.round((z_hi - env.z0) / ROW_M), k0 + 1, env.spine.shape[1]))
    seen = np.isfinite(env.spine[:, k0:k1]).mean(axis=1)
    return np.flatnonzero(seen > 0.5)


def _every(n: int, m: int) -> np.ndarray:
    return np.arange(0, n, n // m)


def _ring_columns(n: int, spacing_m: float, meridian_m: float) -> np.ndarray:
    """The columns a ring keeps: all, or every 2nd, 4th... while its spacing after dropping
    stays at most the meridian's `meridian_m` and 6 points remain."""
    m = n
    while m % 2 == 0 and m // 2 >= 6 and spacing_m * n / (m // 2) <= meridian_m:
        m //= 2
    return _every(n, m)


def _seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """The distance (m) of point p from the segment ab."""
    ab = b - a
    t = float(np.clip((p - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def _thin(ring: np.ndarray, cols: np.ndarray, meridian: np.ndarray) -> np.ndarray:
    """The columns `cols` of a ring (its points `ring` (n, 3) at every column) less those
    whose two kept neighbours lie within the meridian's spacing (`meridian` (n,) m) of each
    other while the point is within `THIN_SAG_M` of the segment between them: where a ring
    runs close to the axis (the sacrum's front, the dome's top) its spacing falls far under
    the meridian's, and the slivers there would set the stable step."""
    cols = np.asarray(cols)
    if len(cols) <= 6:
        return cols
    keep = [int(cols[0])]
    for i in range(1, len(cols)):
        j, nxt = int(cols[i]), int(cols[(i + 1) % len(cols)])
        a, b = ring[keep[-1]], ring[nxt]
        few = len(cols) - i - 1 + len(keep) < 6  # dropping it would leave fewer than 6
        if not few and np.linalg.norm(b - a) <= meridian[j] and _seg_dist(ring[j], a, b) <= THIN_SAG_M:
            continue
        keep.append(j)
    return np.asarray(keep)


def _split_long(ring: np.ndarray, cols: np.ndarray, n: int, h: float) -> tuple:
    """(u, points) of a ring: its points `ring` (n, 3) at columns `cols`, each edge longer
    than `LONG_EDGE` x h split into edges about h long by points on it (u: the column
    coordinate, fractional between columns). Where the ring steps round a bone that juts
    in toward the axis (the vertebral bodies), neighbouring columns lie at far different
    distances from it and one edge spans the step (80-90 mm on myo-sim's lumbar spine, the
    rings 8-12 mm apart: triangles of quality 0.06): points on it leave the surface where
    it was and make its triangles near equilateral."""
    us, ps = [], []
    for i, j in enumerate(cols):
        jn = int(cols[(i + 1) % len(cols)])
        a, b = ring[j], ring[jn]
        un = jn if jn > j else jn + n
        us.append(float(j))
        ps.append(a)
        length = float(np.linalg.norm(b - a))
        if length > LONG_EDGE * h:
            k = int(np.ceil(length / h)) - 1
            for t in np.arange(1, k + 1) / (k + 1):
                us.append(float(j + t * (un - j)))
                ps.append(a + t * (b - a))
    return np.asarray(us), np.asarray(ps)


def _fan(pole: int, ring: np.ndarray, *, up: bool) -> np.ndarray:
    nxt = np.roll(ring, -1)
    return np.stack([ring, nxt, np.full(len(ring), pole)] if up else [np.full(len(ring), pole), nxt, ring], axis=1)


def _stitch(lo: np.ndarray, hi: np.ndarray, vert: np.ndarray) -> np.ndarray:
    """The triangles between ring lo and the ring above it, hi (point indices into `vert`,
    each from column 0 round the axis, of any counts), oriented as quads (lo_j, lo_j+1,
    hi_j+1, hi_j): from column 0 on, the ring whose next point gives the shorter new edge
    across the strip advances (the greedy rule of contour stitching, Christiansen & Sederberg
    1978, Comput Graph 12:187), so that where a ring's step round a bone moves by a column
    from one ring to the next its points still join their nearest."""
    a, b = len(lo), len(hi)
    i = j = 0
    out = []
    while i < a or j < b:
        if i == a or j == b:
            go_lo = i < a
        else:
            go_lo = np.linalg.norm(vert[lo[(i + 1) % a]] - vert[hi[j]]) < np.linalg.norm(
                vert[hi[(j + 1) % b]] - vert[lo[i]]
            )
        if go_lo:
            out.append((lo[i], lo[(i + 1) % a], hi[j % b]))
            i += 1
        else:
            out.append((lo[i % a], hi[(j + 1) % b], hi[j]))
            j += 1
    return np.asarray(out, np.int64)


def _signed_volume(vert: np.ndarray, face: np.ndarray) -> float:
    p = vert[face]
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)


def thoracic_cavity_surface(env: Envelope, lf: Loft) -> tuple:
    """The thoracic cavity's closed surface over the dome: the dome and the zone's top ring
    (reversed), the wall `loft` placed up the rib cage's inner face from the zone's top to
    one top plane under the rib cage's lowest top, closed by a shallow cone. Returns (vert
    (n, 3) m, face (m, 3)), outward."""
    n = lf.columns
    phi = env.phi()
    k_top = max(k for k, kd in enumerate(lf.kind) if kd == "zoa")
    dome_rings = [lf.rings[k] for k in range(k_top, len(lf.rings))]
    wall_z, wall_r = lf.extra["wall_z"], lf.extra["wall_r"]
    n_up = len(wall_z) - 1
    up = [env.frame.point(phi, wall_z[k], wall_r[k]) for k in range(1, n_up + 1)]
    z_hi = wall_z[-1]
    base = np.concatenate([lf.vert[r] for r in dome_rings] + [lf.vert[lf.apex][None]])
    c = up[-1].mean(axis=0)
    # a shallow cone, not a flat disc (whose triangles, in one plane, no crossing test can judge)
    top_pt = c + (float(z_hi.max()) + TOP_MARGIN_M - c @ env.frame.cranial) * env.frame.cranial
    vert = np.concatenate([base, *up, top_pt[None]])
    start = np.cumsum([0] + [len(r) for r in dome_rings])
    d_ring = [start[k] + np.arange(len(dome_rings[k])) for k in range(len(dome_rings))]
    d_apex = int(start[-1])
    w_ring = [d_ring[0]] + [d_apex + 1 + k * n + np.arange(n) for k in range(n_up)]
    top = d_apex + 1 + n_up * n
    dome = np.concatenate(
        [_stitch(d_ring[k], d_ring[k + 1], vert) for k in range(len(d_ring) - 1)] + [_fan(d_apex, d_ring[-1], up=True)]
    )
    faces = [dome[:, [0, 2, 1]]]  # the dome as in the membrane, reversed
    faces += [_stitch(w_ring[k], w_ring[k + 1], vert) for k in range(n_up)]
    faces += [_fan(top, w_ring[-1], up=True)]
    face = np.concatenate(faces).astype(np.int64)
    if _signed_volume(vert, face) < 0:
        face = face[:, [0, 2, 1]]
    return vert, face
