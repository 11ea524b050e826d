"""The membrane in an existing musculoskeletal model: MyoSuite's torso (myo-sim).

models/scenes/myotorso_breathing.toml (also packaged: `hybrid run myotorso_breathing`)
locks myotorso's lumbar spine, adds two rib pairs to its thorax (`rigid.ribs`) and links
the abdomen's rib band to them, through `rigid.mjcf = "myo_sim:myotorso"` (the package
builds the MjSpec; its files are only read). Needs `pip install -e .[myo]`
(part of the `test` extra).
"""

import hashlib
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from hybrid.errors import RigidError

SCENE = Path(__file__).resolve().parents[2] / "models" / "scenes" / "myotorso_breathing.toml"


pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("myo_sim") is None,
    reason="myo_sim (PyPI myo-sim) is not installed: pip install -e '.[myo]'",
)


def _package_hash() -> str:
    import myo_sim

    root = Path(myo_sim.__file__).resolve().parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file() and "__pycache__" not in p.parts:
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def test_packaged_scene_is_the_models_scene():
    from hybrid.scenefile import builtin_scene

    assert builtin_scene("myotorso_breathing").read_text() == SCENE.read_text()


def test_myotorso_breathing_stands_and_breathes_on_its_added_ribs_through_its_first_inspiration():
    """The packaged scene: the lumbar spine locked, two rib pairs added to `torso`, the
    rib band linked to them. Through the first inspiration (1.7 s, 3400 steps; its peak
    at 1.6 s): the thorax stands (its pitch within 1 degree of its start), the band rises
    2-8 mm and so do the ribs' anterior ends, the apex descends 10-25 mm, the linked
    points stay on their sites, the volume is exact, and myo-sim's files are unchanged.
    (The full 12 s run's figures are in docs/composing.md: the same peaks each breath.)"""
    import hybrid

    before = _package_hash()
    sim = hybrid.load(str(SCENE))
    rig = sim.model.rigid
    mjm, d = sim.rigid.mj_model, sim.rigid.mj_data
    counts = dict(zip(*np.unique(np.asarray(rig.link_body), return_counts=True)))
    assert counts == {"rib9_left": 25, "rib9_right": 25, "rib10_left": 66, "rib10_right": 66}  # mirror images
    assert all(mjm.site(int(s)).name.startswith("membrane_hybrid_link_") for s in rig.site_id)
    assert mjm.nu == 210 and mjm.njnt == 18 + 4  # myotorso's muscles and joints, and the 4 rib hinges
    assert rig.settings()["locked"] and len(rig.settings()["locked"]) == 18
    hinges = rig.ribs.joints
    fronts0 = np.array([d.site(f).xpos.copy() for f in rig.ribs.fronts])
    result = hybrid.run(sim, 1.7)
    s = result["summary"]
    assert s["status"] == "ok" and s["steps"] == 3400
    assert s["volume_rel_error_max"] <= 1e-10
    assert s["thorax_pitch_change_deg_max"] <= 1.0  # 0.0075 degrees over the 12 s run measured
    assert 2.0 <= s["rib_lift_mm"] <= 8.0  # 3.78 mm measured
    assert 10.0 <= s["apex_descent_mm"] <= 25.0  # 19.6 mm measured
    assert s["metrics"]["rib_lift_mm"]["t_max_s"] == pytest.approx(1.6, abs=0.1)
    lift_mm = (np.array([d.site(f).xpos for f in rig.ribs.fronts]) - fronts0)[:, 2] * 1e3
    assert np.all((2.0 <= lift_mm) & (lift_mm <= 8.0)), (
        lift_mm
    )  # 3.25, 3.27 (rib 9) and 5.47, 5.45 mm (rib 10) at 1.7 s
    assert s["rigid"]["ribs"]["rib_bodies"] == ["rib9_left", "rib9_right", "rib10_left", "rib10_right"]
    angles = [float(d.joint(j).qpos[0]) for j in hinges]
    assert min(angles) > 1e-3, angles  # each rib turned up by milliradians
    pos = sim.state.vert_pos
    np.testing.assert_array_equal(pos[rig.link_vert], d.site_xpos[rig.site_id])
    for j, site in enumerate(rig.site_id):
        b = mjm.site_bodyid[site]
        np.testing.assert_allclose(
            d.xpos[b] + d.xmat[b].reshape(3, 3) @ mjm.site_pos[site], pos[rig.link_vert[j]], atol=1e-12
        )
    assert _package_hash() == before


def test_missing_package_is_named_with_the_extra(monkeypatch):
    import sys

    from hybrid.model import compile_scene
    from hybrid.scenefile import load_scene

    monkeypatch.setitem(sys.modules, "myo_sim", None)  # import myo_sim raises ImportError
    with pytest.raises(RigidError, match=r"myo_sim.*not installed.*hybrid\[myo\]"):
        compile_scene(load_scene(SCENE))
