"""The scene of a fitted trunk: the lofted surface's regions (by the part each ring belongs
to), its rib band held by articulated ribs added on the model's thoracic body
(`[rigid.ribs]`: no model on the registries has its ribs as separate bodies): the costal
margin's ring linked to them, the zone of apposition above it sliding on them (each point held
to the plane tangent to it at rest, which its rib carries: `RigidLink.slide_stiffness_n_per_m3`),
as the diaphragm's apposed fibres slide along the inner rib cage as the dome descends; the
spine's strip and the pelvic floor nailed, and the breathing terms of `myotorso_breathing`.
Each rib pair hinges at the height of its ribs' vertebrae (`RIB_VERTEBRAE`), so that the ribs slope
down to the front; where the spine names T4 to T8, an upper pair (ribs 4-5, the pulmonary rib cage)
carries the lungs' wall above the border and holds the rib cage's inspiratory muscles, driven each
breath with the diaphragm.

The band is parted as in `models/scenes/myotorso_breathing.toml`: its front (the costal
cartilages, up to `FRONT_DEG` off the anterior midline) to a front pair of ribs, its sides
and back to a lower pair, one free column of points between them, at the anterior midline
and beside the spine (two bodies holding neighbouring points would tear the sheet across
one triangle). Material and rib parameters are that scene's, each with its source there.
Unlike that scene's sphere, the fitted surface has flat and shallow parts that a stress-free
membrane lets bend without stretching: the dome and the abdominal wall hold a tension at rest
(`RestingTension`: the dome's from Laplace's law, the wall's a calibration). The lungs
(`Lungs`, the adult parameters of `hybrid.terms.lungs.ADULT_LUNGS`) fill the cavity over the
dome up to the fitted thoracic cavity's top plane.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hybrid import regions as R
from hybrid.errors import MeshError
from hybrid.scene import Masses, MeshSpec, RibPair, Ribs, Rigid, RigidLink, Scene
from hybrid.schedule import Breathing
from hybrid.terms import Damping, Lungs, Membrane, MuscleFibres, Nailed, PassiveFibres, RestingTension, Volume
from hybrid.terms.lungs import ADULT_LUNGS

from .surface import Loft

__all__ = [
    "FRONT_DEG",
    "TENDON_RISE",
    "RESTING_PDI_PA",
    "ABDOMEN_RESTING_TENSION_N_PER_M",
    "ZONE_SLIDE_N_PER_M3",
    "RIB_VERTEBRAE",
    "UPPER_FRONT_VERTEBRA",
    "RIB_MUSCLE_GEAR_N_M",
    "RIB_MUSCLE_ACTIVATION",
    "DIAPHRAGM_DRIVE_N_PER_M",
    "rib_head_height",
    "vertebra_height",
    "trunk_scene",
    "sectors",
    "dome_radius_m",
    "dome_resting_tension",
]

#: the band's front part, linked to the front pair, reaches this far off the anterior
#: midline (deg; the costal cartilages of the lower ribs)
FRONT_DEG = 40.0
#: the central tendon: the dome above this fraction of its rise (an assumption: the tendon
#: is the dome's top, its muscle the rest)
TENDON_RISE = 0.6
#: the ribs added: capsule radius (m), as `myotorso_breathing`
RIB_RADIUS_M = 0.006
#: the ribs each added pair stands for (anatomy, not a calibration: the costal margin is the
#: cartilages of ribs 7-10, the front's those of ribs 7-8; each rib's head articulates with
#: its own vertebra): the pair's hinge is at the mean height of those thoracic vertebrae, so
#: that the ribs slope down from the spine to the front as real ones do (a rib rising then
#: moves its front forward and out). A model whose spine does not name them keeps the
#: hinge at the band's height (level ribs).
RIB_VERTEBRAE = {"front": (7, 8), "side": (9, 10), "upper": (4, 5)}
#: the upper pair (ribs 4-5, the pulmonary rib cage, under pleural pressure only, carrying the
#: lungs' wall above the border: `Lungs.wall_bodies`): its front, the ribs' sternal ends, level
#: with this fractional vertebra (surface anatomy: the sternal angle, rib 2, lies level with the
#: T4-T5 disc and the xiphisternal joint, rib 7, with T9; the ribs between taken evenly spaced, an
#: assumption: ribs 4 and 5 at 6.3 and 7.2); built where the spine names T4 to T8
UPPER_FRONT_VERTEBRA = 4.5 + (9.0 - 4.5) * (np.mean(RIB_VERTEBRAE["upper"]) - 2.0) / 5.0
#: the rib cage's inspiratory muscles (parasternal intercostals, scalenes) on the upper pair: a motor
#: of this gear on each hinge (N m at activation 1) and the activation's peak in each breath (the
#: `breathing` waveform of the diaphragm's drive): chosen, neither sourced nor calibrated (no source at
#: hand for the torque they put on a rib pair)
RIB_MUSCLE_GEAR_N_M = 1.0
RIB_MUSCLE_ACTIVATION = 0.6
#: the diaphragm's drive, its muscle fibres' peak tension in each breath (N/m): calibration, the one
#: parameter set to a target: a tidal volume of 0.50 L (an adult's quiet breath, 0.4-0.6 L) on
#: myo-sim's torso at mesh level 0 (0.496 L measured at 44 N/m; 0.466 L at 40)
DIAPHRAGM_DRIVE_N_PER_M = 44.0
#: the transdiaphragmatic pressure the relaxed dome holds at rest (Pa): the lungs' resting
#: recoil, pleural pressure -5 cmH2O at FRC (textbooks; docs/lungs.md), across a
#: dome whose abdominal side is at atmospheric pressure (an assumption: no checked source for
#: the gastric pressure at rest)
RESTING_PDI_PA = 5.0 * 98.0665


#: the zone of apposition's hold on the ribs (N/m^3, `RigidLink.slide_stiffness_n_per_m3`): a
#: penalty, chosen, not sourced: the zone's points slide along the inner rib cage and the largest
#: pressures of quiet breathing (about 1 kPa) leave them 0.1 mm off it
ZONE_SLIDE_N_PER_M3 = 1e7

#: the abdominal wall's tension at rest (N/m): calibration, not a source (none at hand for the
#: wall's resting tone): without it the wall, stress-free, kept a fold after each breath (the
#: surface 2.2 mm RMS off its rest shape at the end of expiration), with it 0.15 mm
ABDOMEN_RESTING_TENSION_N_PER_M = 10.0


def dome_radius_m(points: np.ndarray) -> float:
    """The radius (m) of the sphere fitted to the dome's points (n, 3) m by least squares
    (|x|^2 = 2 c . x + k, linear in the centre c and k)."""
    a = np.c_[2.0 * points, np.ones(len(points))]
    sol = np.linalg.lstsq(a, np.sum(points**2, axis=1), rcond=None)[0]
    return float(np.sqrt(sol[3] + sol[:3] @ sol[:3]))


def dome_resting_tension(points: np.ndarray) -> float:
    """The tension (N/m) of the relaxed dome at rest, by Laplace's law on its fitted sphere:
    T = P R / 2, P = `RESTING_PDI_PA`. Without it the stress-free dome and abdominal wall
    bend without stretching (a flat or shallow sheet has no first-order stiffness): the
    fitted trunk's apex sank under a fraction of the drive and stayed down after it."""
    return RESTING_PDI_PA * dome_radius_m(points) / 2.0


def _on(u: np.ndarray, columns, n: int) -> np.ndarray:
    """Which of a ring's points, at column coordinates u (fractional between columns: a
    point on a split edge, `hybrid.anatomy.surface`), belong to the run of neighbouring
    columns `columns`: a point on a column of it, or on a split edge with an end on one of
    its columns. The columns left free between the ribs' sectors and beside the spine stay
    single columns of points, as on rings of whole edges: a run of free points along the
    flat side of a vertebral body, which the rib band's zero resting tension does not hold,
    bent without stretching (13.8 mm off its rest after a breath, the surface 0.78 mm RMS)."""
    cs = np.asarray(columns, np.int64)
    lo, hi = np.floor(u).astype(np.int64) % n, np.ceil(u).astype(np.int64) % n
    return np.where(u == np.floor(u), np.isin(lo, cs), np.isin(lo, cs) | np.isin(hi, cs))


def _idx(points) -> R.Indices:
    return R.Indices(indices=tuple(int(i) for i in np.unique(np.asarray(points, np.int64))))


def sectors(lf: Loft) -> dict:
    """The band's columns of each pair and side: {("front"|"side", "left"|"right"): [j...]}."""
    n = lf.columns
    spine = set(int(j) for j in lf.extra["spine_columns"])
    step = 360.0 / n
    front = [j for j in range(1, n // 2) if j * step <= FRONT_DEG]
    after = (max(front) if front else 0) + 2
    spine_left = [j for j in range(1, n // 2 + 1) if j in spine]
    last = (min(spine_left) if spine_left else n // 2) - 2
    side = list(range(after, last + 1))
    return {
        ("front", "left"): front,
        ("side", "left"): side,
        ("front", "right"): [n - j for j in front],
        ("side", "right"): [n - j for j in side],
    }


def rib_head_height(part: str, lf: Loft, band_pts: np.ndarray, vertebrae: dict) -> float:
    """The height (m along cranial) of the hinge of the pair `part` ("front", "side"): the mean
    of its ribs' vertebrae (`RIB_VERTEBRAE`; vertebrae {level: centre (3,) m}), else the mean
    of its band points (n, 3) m."""
    fr = lf.extra["frame"]
    levels = RIB_VERTEBRAE[part]
    if all(k in vertebrae for k in levels):
        return float(np.mean([vertebrae[k] @ fr.cranial for k in levels]))
    return float(np.mean(band_pts @ fr.cranial))


def vertebra_height(level: float, lf: Loft, vertebrae: dict) -> float | None:
    """The height (m along cranial) of a fractional thoracic `level`, between the centres of
    the vertebrae on either side ({level: centre (3,) m}); None if either is missing."""
    fr = lf.extra["frame"]
    lo, hi = int(np.floor(level)), int(np.ceil(level))
    if lo not in vertebrae or hi not in vertebrae:
        return None
    z_lo, z_hi = float(vertebrae[lo] @ fr.cranial), float(vertebrae[hi] @ fr.cranial)
    return z_lo + (level - lo) * (z_hi - z_lo)


def _head(lf: Loft, spine_pts: np.ndarray, mid: float, z: float) -> np.ndarray:
    """A left rib's costovertebral joint (3,) m: beside the spine's points near height z."""
    fr = lf.extra["frame"]
    sz = spine_pts @ fr.cranial
    near = spine_pts[np.abs(sz - z) < 0.01]
    if not len(near):
        near = spine_pts[np.argsort(np.abs(sz - z))[:50]]
    width = float(np.max(np.abs(near @ fr.left - mid)))
    centre = near.mean(axis=0)
    return centre + (mid - centre @ fr.left + 0.75 * width) * fr.left + (z - centre @ fr.cranial) * fr.cranial


def _upper_pair(lf: Loft, front_pair: RibPair, side_pair: RibPair, spine_pts, mid: float, vertebrae: dict):
    """The upper pair (`UPPER_FRONT_VERTEBRA`), its front over the front pair's at the height of
    its ribs' sternal ends, as wide as the side pair; None where the spine lacks the vertebrae."""
    fr = lf.extra["frame"]
    levels = RIB_VERTEBRAE["upper"]
    z_front = vertebra_height(UPPER_FRONT_VERTEBRA, lf, vertebrae)
    if z_front is None or not all(k in vertebrae for k in levels):
        return None
    z_head = rib_head_height("upper", lf, np.zeros((0, 3)), vertebrae)
    low_front = np.asarray(front_pair.front_m, float)
    front = low_front + (z_front - low_front @ fr.cranial) * fr.cranial
    head = _head(lf, spine_pts, mid, z_head)
    return dataclasses.replace(
        side_pair,
        name="ribs_upper",
        head_m=tuple(float(x) for x in head),
        front_m=tuple(float(x) for x in front),
        muscle_gear_n_m=RIB_MUSCLE_GEAR_N_M,
    )


def _pair(
    name, lf: Loft, band_pts: np.ndarray, spine_pts: np.ndarray, mid: float, clearance_m: float, z: float
) -> RibPair:
    fr = lf.extra["frame"]
    head = _head(lf, spine_pts, mid, z)
    lateral = band_pts @ fr.left - mid
    ok = band_pts[lateral >= 2 * RIB_RADIUS_M]
    tip = ok[int(np.argmax(ok @ fr.anterior))]
    out = tip - fr.axis(tip @ fr.cranial)
    out -= (out @ fr.cranial) * fr.cranial
    front = tip + clearance_m * out / np.linalg.norm(out)
    half = float(lateral.max()) + clearance_m + RIB_RADIUS_M
    return RibPair(
        name=name,
        head_m=tuple(float(x) for x in head),
        front_m=tuple(float(x) for x in front),
        half_width_m=half,
        axis_angle_deg=35.0,
        stiffness_n_m_per_rad=4.0,
        damping_n_m_s_per_rad=0.05,
        mass_kg=0.2,
    )


def trunk_scene(
    lf: Loft,
    *,
    name: str,
    mjcf: str,
    mesh_file: str,
    rib_body: str,
    spine_pts: np.ndarray,
    clearance_m: float,
    fix_root: bool = False,
    vertebrae: dict | None = None,
) -> Scene:
    """The `Scene` of the lofted surface `lf` (module docstring), its mesh read from
    `mesh_file` (relative to the scene's folder), its rigid part `mjcf`, the ribs added on
    `rib_body`, hinged at the heights of their `vertebrae` ({level: centre (3,) m}, the
    skeleton's thoracic vertebrae: `rib_head_height`)."""
    vertebrae = vertebrae or {}
    fr = lf.extra["frame"]
    mid = float(fr.origin @ fr.left)
    kinds = lf.kind
    margin = max(k for k, kd in enumerate(kinds) if kd == "wall")  # the costal margin ring
    band_rings = [margin] + [k for k, kd in enumerate(kinds) if kd == "zoa"]  # up to the zone's top ring
    band = np.concatenate([lf.rings[margin], lf.points_of({"zoa"})])
    dome = np.concatenate([lf.points_of({"dome"}), [lf.apex]])
    tendon = np.concatenate([r for r, k, s in zip(lf.rings, kinds, lf.dome_rise) if k == "dome" and s >= TENDON_RISE])
    tendon = np.concatenate([tendon, [lf.apex]])
    floor = np.concatenate([lf.points_of({"floor"}), [lf.bottom]])
    spine_cols = np.asarray(lf.extra["spine_columns"], np.int64)
    cols = lf.extra["ring_columns"]
    low = [r[_on(c, spine_cols, lf.columns)] for r, c, k in zip(lf.rings, cols, kinds) if k in ("floor", "wall", "zoa")]
    strip = np.concatenate(low) if low else np.zeros(0, np.int64)
    regions: dict = {
        "pelvis": _idx(floor),
        "rib_band": _idx(band),
        "dome": _idx(dome),
        # the lungs' floor: the dome and the zone's top ring, so that the cavity's border (faces
        # with two of their points in it, `hybrid.regions.faces_of`) runs on the rib band's points
        # alone, which the ribs carry, at every mesh level; on the dome's own faces it zigzags
        # between the band and the dome's first ring, half of it carried at level 0, a sixth at 1
        "lung_floor": _idx(np.concatenate([dome, lf.rings[band_rings[-1]]])),
        "diaphragm": R.Union_(parts=("rib_band", "dome")),
        "abdomen": R.Difference(base="all", minus="diaphragm"),
        "tendon": _idx(tendon),
        "muscle": R.Difference(base="diaphragm", minus="tendon"),
        "spine_strip": _idx(strip),
        "spine": R.Difference(base="spine_strip", minus="pelvis"),
        "fixed": R.Union_(parts=("spine", "pelvis")),
        "moving": R.Difference(base="all", minus="fixed"),
    }
    if any(not np.isin(np.arange(lf.columns), cols[k]).all() for k in band_rings):
        raise MeshError("expected the rib band's rings to hold every column, received a thinned ring")
    pairs, links = [], []
    for (part, side), sector in sectors(lf).items():
        if not sector:
            continue
        # the costal margin's ring follows its ribs; the zone above it slides on them
        rib = f"ribs_{part}_{side}"
        margin_pts = lf.rings[margin][_on(cols[margin], sector, lf.columns)]
        zone_pts = np.concatenate([lf.rings[k][_on(cols[k], sector, lf.columns)] for k in band_rings[1:]])
        regions[f"{rib}_points"] = _idx(margin_pts)
        regions[f"{rib}_zone"] = _idx(zone_pts)
        links.append(RigidLink(region=f"{rib}_points", body=rib, name=rib))
        links.append(
            RigidLink(region=f"{rib}_zone", body=rib, name=f"{rib}_zone", slide_stiffness_n_per_m3=ZONE_SLIDE_N_PER_M3)
        )
        if side == "left":  # the ribs placed by the sector's own columns
            whole = np.concatenate([lf.rings[k][np.isin(cols[k], sector)] for k in band_rings])
            z_head = rib_head_height(part, lf, lf.vert[whole], vertebrae)
            pairs.append(_pair(f"ribs_{part}", lf, lf.vert[whole], spine_pts, mid, clearance_m, z_head))
    by_name = {p.name: p for p in pairs}
    upper = None
    if "ribs_front" in by_name and "ribs_side" in by_name:
        upper = _upper_pair(lf, by_name["ribs_front"], by_name["ribs_side"], spine_pts, mid, vertebrae)
    ctrl: dict = {}
    if upper is not None:
        pairs.append(upper)
        ctrl = {"ribs_upper_*_muscle": Breathing(period_s=4.0, inspiration_fraction=0.4, peak=RIB_MUSCLE_ACTIVATION)}
    apex = lf.vert[lf.apex]
    axis_pt = fr.axis(lf.z_in)  # the hoops' axis: the cavity's, straight through the abdomen
    forces = (
        Membrane(name="diaphragm_elasticity", region="diaphragm", youngs_modulus_n_per_m=20.0, poisson_ratio=0.3),
        Membrane(name="tendon_elasticity", region="tendon", youngs_modulus_n_per_m=500.0, poisson_ratio=0.3),
        Membrane(name="abdomen_elasticity", region="abdomen", youngs_modulus_n_per_m=20.0, poisson_ratio=0.3),
        PassiveFibres(
            name="abdomen_hoops",
            region="abdomen",
            modulus_n_per_m=600.0,
            around_axis=tuple(float(x) for x in fr.cranial),
            axis_point_m=tuple(float(x) for x in axis_pt),
        ),
        MuscleFibres(
            name="muscle",
            region="muscle",
            toward_m=tuple(float(x) for x in apex),
            tension_n_per_m=Breathing(period_s=4.0, inspiration_fraction=0.4, peak=DIAPHRAGM_DRIVE_N_PER_M),
            force_length_width=0.67,
        ),
        RestingTension(
            name="dome_resting_tension", region="dome", tension_n_per_m=round(dome_resting_tension(lf.vert[dome]), 2)
        ),
        RestingTension(
            name="abdomen_resting_tension", region="abdomen", tension_n_per_m=ABDOMEN_RESTING_TENSION_N_PER_M
        ),
        Damping(region="moving", drag_n_s_per_m3=200.0),
        # the lungs fill the cavity over the dome, up to the fitted thoracic cavity's top plane
        # (thorax.obj's); the rib band, the zone of apposition, is the abdomen's wall, not theirs
        # (but its top ring, where the dome leaves the ribs: `lung_floor`)
        Lungs(
            name="lungs",
            floor="lung_floor",
            wall_height_m=round(float(lf.extra["wall_z"][-1].max() - np.mean(lf.z_top)), 4),
            wall_bodies="ribs_upper_*" if upper is not None else None,
            **ADULT_LUNGS,
        ),
    )
    constraints = (Nailed(name="spine", region="spine"), Nailed(name="pelvis", region="pelvis"), Volume())
    rigid = Rigid(
        mjcf=mjcf,
        links=tuple(links),
        prefix="membrane_",
        add_link_mass=True,
        lock=("*",),
        fix_root=fix_root,
        ctrl=ctrl,
        ribs=Ribs(
            body=rib_body,
            pairs=tuple(pairs),
            anterior=tuple(float(x) for x in fr.anterior),
            cranial=tuple(float(x) for x in fr.cranial),
            radius_m=RIB_RADIUS_M,
            sternum_stiffness_n_per_m=1000.0,
            sternum_damping_n_s_per_m=0.5,
        ),
    )
    return Scene(
        mesh=MeshSpec(generator=None, path=mesh_file),
        masses=Masses(total_kg=4.0),
        regions=regions,
        forces=forces,
        constraints=constraints,
        rigid=rigid,
        dt_s="auto",
        integrator="symplectic_euler",
        formulation="continuum",
        duration_s=12.0,
        name=name,
    )
