"""The built-in scenes written in Python: the membrane-only breathing demo, and the
breathing trunk with lungs (the packaged `breathing` scene file and one term more). (The
coupled breathing trunk is a TOML file in `models/scenes/`; the benchmark's
membranes are in `hybrid.bench`.)"""

from __future__ import annotations

import dataclasses

from . import scenefile
from .regions import Difference, HalfSpace
from .scene import Damping, Gravity, Lungs, Masses, MeshSpec, Muscle, Nailed, Scene, ShapeMemory, Volume
from .schedule import Breathing
from .terms.lungs import ADULT_LUNGS

__all__ = ["membrane_demo", "breathing_lungs"]

RADIUS_M = 0.12


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
    thorax (`hybrid.terms.lungs`), every lung parameter from a source, none fitted:
    lung compliance 0.2 L/cmH2O (Guyton, Textbook of Medical Physiology), resting recoil
    5 cmH2O (pleural pressure -5 cmH2O at rest, physiology textbooks), airway resistance
    1.5 cmH2O s/L (DuBois et al. 1956, J Clin Invest 35:327), spontaneous breathing (the
    airway open at 0 cmH2O); a thoracic cavity 0.12 m high over the dome's border, about 3 L
    at rest (a functional residual capacity of about 3 L, textbooks; the linear law does not
    depend on it). The cavity's floor is the dome above the rib band: the band, the zone of
    apposition the lower ribs hold, is the abdomen's wall (the abdominal rib cage), not the lungs'
    (Mead & Loring 1982), so that the lung volume change is the pulmonary rib cage's, the
    abdominal rib cage's and the abdomen's displacements. The trunk's geometry and drive are the
    `breathing` scene's: it is small for an adult (a tidal volume near 0.14 L, not 0.5 L;
    docs/lungs.md)."""
    base = scenefile.load_scene(scenefile.builtin_scene("breathing"))
    lungs = Lungs(
        floor=Difference(base="diaphragm", minus="rib_band"),
        wall_height_m=0.12,
        **ADULT_LUNGS,
    )
    return dataclasses.replace(base, name="breathing_lungs", forces=(*base.forces, lungs))
