"""The packaged scene `myotorso_breathing`: the trunk `fit_trunk` fits to MyoSuite's torso
(myo-sim), written into the package's models/scenes with the run settings below, so that
`hybrid run myotorso_breathing` breathes on the model's own anatomy without fitting it at
each load. `python -m hybrid.anatomy.packaged [MODELS_SCENES_DIR]` writes it again (after a
change of the fit); `tests/test_anatomy_packaged.py` checks that the packaged files are what
the fit gives now.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from ..scene import Scene
from ..scenefile.write import scene_to_toml
from .fit import fit_trunk

__all__ = ["MODEL", "NAME", "HEADER", "packaged_scene", "write_packaged"]

MODEL = "myo_sim:myotorso"
NAME = "myotorso_breathing"
#: the run settings of the packaged scene: implicit Euler at 2 ms. Measured on one 4 s breath at
#: level 0 against symplectic Euler at its stable 0.1 ms (49 s of CPU, here 6): tidal volume
#: 0.5002 against 0.4997 L, apex descent 28.57 against 28.56 mm, pulmonary rib cage share 0.176
#: against 0.175, rib lift 2.680 against 2.715 mm (1.3% low: first order in the step); at 5 ms the
#: rib lift is 2.6% low, at 10 ms 3.0%
RUN = {"integrator": "implicit_euler", "dt_s": 2e-3, "duration_s": 12.0}
#: the joints whose moments the loads readout reports: myotorso's L5/S1 (`flex_extension`, lumbar5
#: on the sacrum), about which the abdomen's pressure turns the trunk
LOAD_JOINTS = ("flex_extension",)

HEADER = """\
# The breathing trunk in MyoSuite's torso (myo-sim), fitted to the model's own skeleton: the
# abdomen and diaphragm (one closed membrane) and the lungs' cavity over its dome, built from
# the rib cage, spine and pelvis of myo_sim:myotorso by `hybrid anatomy` (docs/anatomy.md),
# on rib pairs added to its thorax. Three quiet breaths (15 a minute, inspiration 40% of the
# cycle).
#
# Written by `python -m hybrid.anatomy.packaged` from the fit: not edited by hand (the tests
# check that it is what the fit gives). Fit your own model with `hybrid anatomy MODEL --out DIR`.
#
# rigid.mjcf = "myo_sim:myotorso" is myo_sim.load_spec("myotorso") (pip install 'hybrid[myo]'),
# built in memory from the package's files, which are only read. Frame: z cranial, -y anterior,
# +x to the left; the pelvis welded to the world, the lumbar spine and the thorax locked where
# they start (rigid.lock), so that the thorax stands (its 210 muscles stay at zero control);
# the loads readout reports the moments about L5/S1 (rigid.load_joints, myotorso's flex_extension).
#
# The membrane (myotorso_breathing/abdomen.obj, 2,702 points): the pelvic floor (nailed) from
# the sacrum's tip to the pelvic inlet; the abdominal wall up to the costal margin; the zone of
# apposition along the lower ribs' inner face (29% of it: Mead 1979, a quarter to a third),
# sliding on the ribs that carry it; the dome over it, its top 40% the central tendon; the spine's
# strip nailed. Abdomen 8.18 L (adults 7.86 +/- 2.04 L, CT of 61 adults, PMID 33226496). Rib
# pairs added on `torso` ([rigid.ribs]), each hinged at the mean height of its ribs' vertebrae
# (read from the model): the costal cartilages of ribs 7-8 (front), ribs 9-10 (sides and back),
# and ribs 4-5 (the pulmonary rib cage, carrying the lungs' wall, with the rib cage's
# inspiratory muscles).
#
# Where each parameter comes from (hybrid/anatomy/trunk_scene.py):
# - membrane moduli (20 N/m, the tendon 500 N/m), the abdominal wall's hoops (600 N/m), drag,
#   mass, the rib hinges (4 N m/rad) and the sternum (1,000 N/m): models/scenes/breathing.toml's;
# - the dome's resting tension: Laplace's law at a resting transdiaphragmatic pressure of
#   5 cmH2O over the fitted dome's radius (derived); the abdominal wall's 10 N/m: calibration;
# - lungs: compliance 0.2 L/cmH2O, resting recoil 5 cmH2O, airway resistance 1.5 cmH2O s/L,
#   each from its source (hybrid.terms.lungs.ADULT_LUNGS, docs/lungs.md);
# - the diaphragm's drive, 44 N/m: calibrated to a 0.50 L tidal volume at level 0
#   (calibration, not validation);
# - the rib cage's inspiratory muscles (a 1 N m motor on each upper hinge, activation 0.6 at
#   each breath's peak) and the zone's sliding penalty (1e7 N/m^3): chosen, not sourced.
#
# Integrator: implicit Euler at 2 ms (hybrid.anatomy.packaged.RUN: within 0.5% of symplectic
# Euler at its 0.1 ms on the breath's tidal volume, apex and shares, 1.3% on the rib lift).
# What it predicts against an adult's quiet breathing, and what it misses: docs/anatomy.md.

"""


def packaged_scene(out_dir: str | Path) -> Scene:
    """Fit the packaged model's trunk into out_dir (its abdomen.obj, thorax.obj and a scene
    file, as `hybrid anatomy` writes them) and return the packaged scene: that fit with the
    run settings `RUN`, its mesh read from `NAME/abdomen.obj` beside the scene file."""
    fit = fit_trunk(MODEL, out_dir, name=NAME)
    from ..scenefile import load_scene

    scene = load_scene(fit.scene_path)
    mesh = dataclasses.replace(scene.mesh, path=f"{NAME}/{fit.abdomen_path.name}")
    rigid = dataclasses.replace(scene.rigid, load_joints=LOAD_JOINTS)
    return dataclasses.replace(scene, mesh=mesh, rigid=rigid, **RUN)


def write_packaged(scenes_dir: str | Path) -> tuple[Path, Path]:
    """Write the packaged scene into scenes_dir (the repository's models/scenes): NAME.toml
    and NAME/abdomen.obj (the fit's other files, its thoracic cavity and its own scene file,
    not kept). Returns their paths."""
    scenes_dir = Path(scenes_dir)
    folder = scenes_dir / NAME
    scene = packaged_scene(folder)
    for other in ("thorax.obj", f"{NAME}.toml"):
        (folder / other).unlink()
    toml = scenes_dir / f"{NAME}.toml"
    toml.write_text(HEADER + scene_to_toml(scene))
    return toml, folder / "abdomen.obj"


if __name__ == "__main__":  # pragma: no cover - a maintainer's command
    from ..scenefile.packaged import packaged_model

    target = sys.argv[1] if len(sys.argv) > 1 else packaged_model("scenes")
    for path in write_packaged(target):
        print(path)
