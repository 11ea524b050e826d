"""The built-in scenes written in Python: the membrane-only breathing demo, and the
breathing trunk with lungs (the packaged `breathing` scene file and one term more). (The
coupled breathing trunk is a TOML file in `models/scenes/`; the benchmark's
membranes are in `hybrid.bench`.)"""

from __future__ import annotations

import dataclasses

from . import scenefile
from .regions import Difference, HalfSpace
from .scene import (
    Damping,
    Gravity,
    Lungs,
    Masses,
    MeshSpec,
    Muscle,
    Nailed,
    RibPair,
    Ribs,
    Scene,
    ShapeMemory,
    Volume,
)
from .schedule import Breathing
from .terms.fibres import MuscleFibres
from .terms.lungs import ADULT_LUNGS

__all__ = [
    "membrane_demo",
    "breathing_lungs",
    "with_upper_ribs",
    "UPPER_RIBS",
    "UPPER_RIB_WALL_TOP_M",
    "UPPER_RIB_ACTIVATION",
]

RADIUS_M = 0.12

#: the breathing trunk's upper rib pair, the pulmonary rib cage: hinged on the spine 0.14 m up and
#: sloping down to its front 0.10 m up (the lower pair, the trunk's rib band, spans 0.045-0.08 m),
#: the rib cage's inspiratory muscles (parasternal intercostals, scalenes) a motor of 2 N m on
#: each hinge. Geometry, stiffness (the builder's 12 N m/rad), gear and damping are chosen, not
#: sourced. The damping (0.5 N m s/rad; the builder's 0.05 otherwise) is the chest wall's tissue
#: resistance on the pair, which MuJoCo takes implicitly; its springs MuJoCo takes explicitly. The
#: pair's fastest mode (both ribs lifting, the sternal spring stretched by their 35-degree axes)
#: is at 69.8 rad/s: at 30 ms h omega = 2.09, whose stable limit is 2.24 at 0.05 and 3.79 at 0.5
#: (`hybrid.rigid.modes`, `hybrid inspect`). At 0.05 the pair went unstable under implicit
#: Euler's large steps (the realtime row, level 8 at 30 ms: its two ribs swinging apart from 2 s
#: on; with the muscles off it stayed at rest); 0.2 holds it (h c / I = 2.1 at 30 ms).
UPPER_RIBS = RibPair(
    name="upper_ribs",
    head_m=(-0.13, 0.025, 0.14),
    front_m=(0.10, 0.012, 0.10),
    half_width_m=0.12,
    damping_n_m_s_per_rad=0.5,
    muscle_gear_n_m=2.0,
)
#: the height (m) of the thoracic cavity's top over the upper rib pair: its wall's rings meet the
#: upper ribs at their own height (0.10-0.14 m), where the pleural pull on a rib sloping down to
#: the front turns it down about its hinge (the sign of the paradox depends on it)
UPPER_RIB_WALL_TOP_M = 0.165
#: the upper ribs' muscles' peak activation in each breath (of 1), with the diaphragm's waveform
UPPER_RIB_ACTIVATION = 1.0
#: the top of the trunk's rib band (m): the dome's border, where the lungs' wall starts
_BAND_TOP_M = 0.08


def membrane_demo(duration_s: float = 12.0) -> Scene:
    """The paper's abdomen-diaphragm sphere without ribs: 80 points, 4 kg,
    incompressible, the top cap muscular (fibres along the meridians toward
    the apex), the bottom nailed; three quiet breaths at 15 per minute."""
    return Scene(
        formulation="paper",
        name="membrane_demo",
        mesh=MeshSpec(generator="uv_sphere", radius_m=RADIUS_M),
        masses=Masses(total_kg=4.0),
        regions={
            "diaphragm": HalfSpace((0.0, 0.0, 0.05), (0.0, 0.0, 1.0)),
            "pelvis": HalfSpace((0.0, 0.0, -0.09), (0.0, 0.0, -1.0)),
        },
        forces=(
            Gravity(),
            ShapeMemory(3000.0),
            Damping(critical_fraction=0.3),
            Muscle(
                "diaphragm", Breathing(period_s=4.0, inspiration_fraction=0.4, peak=60.0), toward_m=(0.0, 0.0, RADIUS_M)
            ),
        ),
        constraints=(Nailed("pelvis"), Volume()),
        dt_s=1e-3,
        integrator="symplectic_euler",
        duration_s=duration_s,
    )


def breathing_lungs() -> Scene:
    """The breathing trunk (`breathing`, models/scenes/breathing.toml) with lungs in its
    thorax (`hybrid.terms.lungs`) and an upper rib pair carrying their wall, every lung
    parameter from a source, none fitted: lung compliance 0.2 L/cmH2O (Guyton, Textbook of
    Medical Physiology), resting recoil 5 cmH2O (pleural pressure -5 cmH2O at rest, physiology
    textbooks), airway resistance 1.5 cmH2O s/L (DuBois et al. 1956, J Clin Invest 35:327),
    spontaneous breathing (the airway open at 0 cmH2O). The cavity's floor is the dome above
    the rib band: the band, the zone of apposition the lower ribs hold, is the abdomen's wall
    (the abdominal rib cage), not the lungs' (Mead & Loring 1982), so that the lung volume
    change is the pulmonary rib cage's, the abdominal rib cage's and the abdomen's
    displacements. The cavity's wall rises from the dome's border (0.08 m) to
    `UPPER_RIB_WALL_TOP_M` and rides on the upper rib pair (`UPPER_RIBS`, the pulmonary rib
    cage, under the pleural pressure and its own muscles only), whose muscles the scene drives
    with the diaphragm's waveform (`rigid.ctrl`, peak `UPPER_RIB_ACTIVATION`): quiet breathing
    with both, as a subject breathes; without `rigid.ctrl`, the diaphragm alone. The pair and
    its muscles are chosen, not sourced. The trunk's geometry and the diaphragm's drive are
    the `breathing` scene's: it is small for an adult (a tidal volume near 0.17 L, not 0.5 L;
    docs/lungs.md)."""
    base = scenefile.load_scene(scenefile.builtin_scene("breathing"))
    drive = next(f.tension_n_per_m for f in base.forces if isinstance(f, MuscleFibres))
    lungs = Lungs(floor=Difference(base="diaphragm", minus="rib_band"), wall_height_m=0.12, **ADULT_LUNGS)
    with_lungs = dataclasses.replace(base, name="breathing_lungs", forces=(*base.forces, lungs))
    muscles = dataclasses.replace(drive, peak=UPPER_RIB_ACTIVATION)  # the diaphragm's waveform
    return with_upper_ribs(with_lungs, muscles, UPPER_RIB_WALL_TOP_M - _BAND_TOP_M)


def with_upper_ribs(scene: Scene, muscles, wall_height_m: float) -> Scene:
    """`scene` (with lungs and a rigid part) given the upper rib pair `UPPER_RIBS` on its body
    "spine", carrying its lungs' wall, now `wall_height_m` high over the dome's border; the pair's
    muscles driven by the schedule `muscles` (None: the diaphragm alone, no `rigid.ctrl`)."""
    ctrl = {} if muscles is None else {"upper_ribs_*_muscle": muscles}
    rigid = dataclasses.replace(scene.rigid, ribs=Ribs(body="spine", pairs=(UPPER_RIBS,)), ctrl=ctrl)
    forces = tuple(
        dataclasses.replace(f, wall_height_m=wall_height_m, wall_bodies="upper_ribs_*") if isinstance(f, Lungs) else f
        for f in scene.forces
    )
    return dataclasses.replace(scene, rigid=rigid, forces=forces)
