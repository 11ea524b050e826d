"""`fit_trunk`: from a model's skeleton to the mesh files and scene of its abdomen and
diaphragm (`hybrid.anatomy.surface`, `hybrid.anatomy.trunk_scene`), with what was measured
on them: the volumes and how far any bone reaches into the membrane."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from hybrid.errors import MeshError, SceneError
from hybrid.kernel import jit
from hybrid.mesh.cavity import open_edges
from hybrid.mesh.intersect import crossing_faces
from hybrid.mesh.obj import write_obj
from hybrid.rigid.skeleton import read_skeleton
from hybrid.scenefile.write import scene_to_toml

from .envelope import MIDLINE_M, dense_points, envelope_of, frame_of
from .surface import loft, thoracic_cavity_surface
from .trunk_scene import trunk_scene

__all__ = ["TrunkFit", "fit_trunk", "penetration_m", "winding_number"]

#: adult reference volumes the fit is set against (L): (low, high, source)
ABDOMEN_REF_L = (5.8, 9.9, "abdominal cavity by CT volume rendering, 7.86 +/- 2.04 L in 61 adults (PMID 33226496)")
#: what the thoracic cavity holds at least, for comparison (no checked source for the cavity's own volume)
THORAX_NOTE = (
    "the lungs alone hold 4.07 +/- 1.19 L at total lung capacity supine (CT, 100 adults: Cressoni et al. 2013, "
    "Crit Care 17:R93), their tissue and blood about 0.72 L (Pierce et al. 1979, Thorax 34:726)"
)


@dataclass
class TrunkFit:
    """What `fit_trunk` wrote (paths) and measured: volumes (L), the largest penetration (mm)
    of each role's bones into the membrane, the zone of apposition's share of the rib cage's
    inner surface and its fraction of the rib cage's height, points and faces."""

    scene_path: Path
    abdomen_path: Path
    thorax_path: Path
    abdomen_volume_l: float
    thorax_volume_l: float
    penetration_mm: dict
    zoa_area_share: float
    zoa_fraction: float
    zoa_gap_mm: tuple
    points: int
    faces: int
    heights_m: dict = field(default_factory=dict)

    def lines(self) -> list:
        pen = ", ".join(f"{k} {v:.1f} mm" for k, v in self.penetration_mm.items())
        h = ", ".join(f"{k} {v:.3f}" for k, v in self.heights_m.items())
        return [
            f"scene {self.scene_path}",
            f"membrane {self.abdomen_path.name}: {self.points} points, {self.faces} triangles, closed, no crossing",
            f"abdomen {self.abdomen_volume_l:.2f} L (adults {ABDOMEN_REF_L[0]}-{ABDOMEN_REF_L[1]} L: {ABDOMEN_REF_L[2]})",
            f"thoracic cavity {self.thorax_volume_l:.2f} L ({self.thorax_path.name}: over the dome, up the rib cage, "
            f"closed, no crossing; {THORAX_NOTE})",
            f"bones inside the membrane, deepest: {pen}",
            f"zone of apposition: {100 * self.zoa_area_share:.0f}% of the rib cage's inner surface "
            f"({100 * self.zoa_fraction:.0f}% of its height); its points' distance to the nearest rib: median "
            f"{self.zoa_gap_mm[0]:.1f} mm, 90th percentile {self.zoa_gap_mm[1]:.1f} mm",
            f"heights (m along cranial): {h}",
        ]


@jit
def _winding(tri: np.ndarray, points: np.ndarray, out: np.ndarray) -> None:
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        total = 0.0
        for f in range(tri.shape[0]):
            ax, ay, az = tri[f, 0, 0] - px, tri[f, 0, 1] - py, tri[f, 0, 2] - pz
            bx, by, bz = tri[f, 1, 0] - px, tri[f, 1, 1] - py, tri[f, 1, 2] - pz
            cx, cy, cz = tri[f, 2, 0] - px, tri[f, 2, 1] - py, tri[f, 2, 2] - pz
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            num = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
            den = la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la
            den += (cx * ax + cy * ay + cz * az) * lb
            total += 2.0 * np.arctan2(num, den)
        out[i] = total / (4.0 * np.pi)


def winding_number(vert: np.ndarray, face: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The closed surface's winding number (about 1 inside, 0 outside) at each point (n, 3):
    the solid angles of its triangles (Van Oosterom & Strackee 1983) over 4 pi."""
    out = np.empty(len(points))
    _winding(np.ascontiguousarray(vert[face], dtype=np.float64), np.ascontiguousarray(points, dtype=np.float64), out)
    return out


def penetration_m(vert: np.ndarray, face: np.ndarray, points: np.ndarray) -> float:
    """The largest distance (m) from the surface of any of `points` inside it (0 for none):
    how deep a bone reaches into the closed surface, on the triangles, not the nearest point."""
    lo, hi = vert.min(axis=0), vert.max(axis=0)
    cand = points[np.all((points >= lo) & (points <= hi), axis=1)]
    if not len(cand):
        return 0.0
    inside = cand[winding_number(vert, face, cand) > 0.5]
    if not len(inside):
        return 0.0
    tri = vert[face]
    deepest = 0.0
    for p in inside:
        q = trimesh.triangles.closest_point(tri, np.repeat(p[None], len(tri), axis=0))
        deepest = max(deepest, float(np.min(np.linalg.norm(q - p, axis=1))))
    return deepest


def _volume(vert, face) -> float:
    p = vert[face]
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)


def _check_closed(vert, face, what: str) -> None:
    bad = open_edges(face)
    if bad:
        raise MeshError(f"{what}: expected a closed, consistently oriented surface, received {len(bad)} open edges")
    pairs, count = crossing_faces(vert, face)
    if count:
        raise MeshError(f"{what}: expected a surface that does not cross itself, received {count} crossing face pairs")


def fit_trunk(
    mjcf: str,
    out_dir: str | Path,
    *,
    name: str = "fitted_trunk",
    columns: int = 48,
    clearance_m: float = 0.005,
    zoa_area_share: float = 0.29,
    dome_rise_m: float = 0.03,
    base_dir: str | None = None,
) -> TrunkFit:
    """Fit the abdomen and diaphragm to the skeleton of `mjcf` (as `rigid.mjcf` names a
    model) and write, in `out_dir` only, `abdomen.obj` (the membrane), `thorax.obj` (the
    thoracic cavity over its dome) and `NAME.toml` (the scene). `columns`: points around;
    `clearance_m`: the membrane's distance inside the bones; `zoa_area_share`: the zone of
    apposition's share of the rib cage's inner surface (Mead 1979: 1/4 to 1/3 in quiet
    breathing upright); `dome_rise_m`: the dome's apex above the zone's highest point (an
    assumption). RigidError for a model without a rib cage, spine or pelvis (one line naming
    what is missing); SceneError or MeshError for parameters or a skeleton it cannot fit."""
    for key, v, lo, hi in (
        ("columns", columns, 12, 512),
        ("clearance_m", clearance_m, 0.0, 0.05),
        ("zoa_area_share", zoa_area_share, 0.01, 0.9),
        ("dome_rise_m", dome_rise_m, 0.0, 0.2),
    ):
        if not (isinstance(v, (int, float)) and lo <= v <= hi) or (key == "columns" and (int(v) != v or v % 2)):
            extra = ", even" if key == "columns" else ""
            raise SceneError(f"fit_trunk {key}: expected a number in [{lo}, {hi}]{extra}, received {v!r}")
    sk = read_skeleton(mjcf, base_dir)
    rib, sp, pel = (dense_points(sk.of(r)) for r in ("rib_cage", "spine", "pelvis"))
    fr = frame_of(rib, sp, pel)
    env = envelope_of(fr, rib, sp, pel, int(columns))
    _, zp, _ = fr.cyl(pel)
    off = pel - fr.origin
    mid = np.abs(off @ fr.left) < MIDLINE_M
    behind = off @ fr.anterior < 0
    if not (mid & behind).any():
        raise MeshError(
            f"MJCF {sk.label}: expected pelvis bones on the midline behind the cavity (the sacrum), received none"
        )
    z_in = float(zp[mid].max())  # the sacral promontory (or the pelvis's top on the midline)
    # the floor's lowest point: the sacrum's (coccyx's) tip where the model names one, the
    # level of the pelvic floor behind; else the pelvis's lowest point on the midline behind
    sacral = [b for b in sk.of("pelvis") if re.search(r"sacr|cocc", f"{b.geom} {b.mesh}", re.IGNORECASE)]
    if sacral:
        zs_ = fr.cyl(np.concatenate([b.vert for b in sacral]))[1]
        z_floor = float(zs_.min())
    else:
        z_floor = float(zp[mid & behind].min())
    lf = loft(env, z_in, z_floor, clearance_m=clearance_m, zoa_area_share=zoa_area_share, dome_rise_m=dome_rise_m)
    lf.extra["frame"] = fr
    _check_closed(lf.vert, lf.face, "the fitted membrane")
    tv, tf = thoracic_cavity_surface(env, lf)
    _check_closed(tv, tf, "the fitted thoracic cavity")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    abdomen_path, thorax_path, scene_path = out / "abdomen.obj", out / "thorax.obj", out / f"{name}.toml"
    rib_bodies = sk.bodies("rib_cage")
    rib_body = max(rib_bodies, key=lambda b: sum(len(x.vert) for x in sk.of("rib_cage") if x.body == b))
    model = mjcf
    if ":" not in mjcf and mjcf not in ("trunk",):
        model = str((Path(base_dir or ".") / mjcf).resolve())
    scene = trunk_scene(
        lf,
        name=name,
        mjcf=model,
        mesh_file=abdomen_path.name,
        rib_body=rib_body,
        spine_pts=sp,
        clearance_m=clearance_m,
        fix_root=sk.free_root,
        vertebrae=sk.thoracic(),
    )
    pen = {}
    for role in ("rib_cage", "pelvis", "spine"):
        pts = np.concatenate([b.vert for b in sk.of(role)])
        pen[role] = 1e3 * penetration_m(lf.vert, lf.face, pts)
    # how close the zone of apposition lies to the ribs: its points' distance to the rib
    # cage's surface (sampled at most SAMPLE_M apart along its edges)
    margin = max(k for k, kd in enumerate(lf.kind) if kd == "wall")
    band = np.concatenate([lf.rings[margin], lf.points_of({"zoa"})])
    gap = cKDTree(rib).query(lf.vert[band])[0]
    write_obj(abdomen_path, lf.vert, lf.face)
    write_obj(thorax_path, tv, tf)
    header = (
        f"# The abdomen and diaphragm fitted to the skeleton of {mjcf} by `hybrid anatomy` (hybrid.anatomy):\n"
        f"# {abdomen_path.name} lofted from the pelvic floor to the dome over the costal margin; regions by the\n"
        f"# part of the surface each point was built in; the rib band linked to ribs added on {rib_body!r}.\n"
    )
    scene_path.write_text(header + scene_to_toml(scene))
    return TrunkFit(
        scene_path=scene_path,
        abdomen_path=abdomen_path,
        thorax_path=thorax_path,
        abdomen_volume_l=1e3 * _volume(lf.vert, lf.face),
        thorax_volume_l=1e3 * _volume(tv, tf),
        penetration_mm=pen,
        zoa_area_share=lf.zoa_area_share,
        zoa_fraction=lf.zoa_fraction,
        zoa_gap_mm=(1e3 * float(np.median(gap)), 1e3 * float(np.percentile(gap, 90))),
        points=len(lf.vert),
        faces=len(lf.face),
        heights_m={
            "pelvic floor": lf.z_floor,
            "pelvic inlet": lf.z_in,
            "costal margin lowest": float(lf.z_cm.min()),
            "costal margin highest": float(lf.z_cm.max()),
            "zone top highest": float(lf.z_top.max()),
            "dome apex": lf.z_apex,
            **{
                f"{p.name} hinge": float((np.asarray(p.head_m) - fr.origin) @ fr.cranial)
                for p in scene.rigid.ribs.pairs
            },
        },
    )
