"""The built-in scene written in Python: the membrane-only breathing demo. (The
coupled breathing trunk is a TOML file in `models/scenes/`; the benchmark's
membranes are in `hybrid.bench`.)"""

from __future__ import annotations

from .regions import HalfSpace
from .scene import Damping, Gravity, Masses, MeshSpec, Muscle, Nailed, Scene, ShapeMemory, Volume
from .schedule import Breathing

__all__ = ["membrane_demo"]

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
