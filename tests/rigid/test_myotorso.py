"""The membrane in an existing musculoskeletal model: MyoSuite's torso (myo-sim).

models/scenes/myotorso_breathing.toml (also packaged: `hybrid run myotorso_breathing`)
links the abdomen's rib border to myotorso's thorax, its spine points to the lumbar
bodies and its pelvis points to the sacrum, through `rigid.mjcf = "myo_sim:myotorso"`
(the package builds the MjSpec; its files are only read). Needs `pip install -e .[myo]`
(part of the `test` extra).
"""

import hashlib
import importlib.util

import numpy as np
import pytest
from pathlib import Path

from hybrid.errors import RigidError


SCENE = Path(__file__).resolve().parents[2] / "models" / "scenes" / "myotorso_breathing.toml"


pytestmark = pytest.mark.skipif(importlib.util.find_spec("myo_sim") is None,
                                reason="myo_sim (PyPI myo-sim) is not installed: pip install -e '.[myo]'")


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


def test_myotorso_breathing_runs_1000_steps_with_exact_volume():
    import mujoco
    import hybrid
    before = _package_hash()
    sim = hybrid.load(str(SCENE))
    rig = sim.model.rigid
    mjm, d = sim.rigid.mj_model, sim.rigid.mj_data
    # the links: rib border on the thorax, spine on lumbar bodies, pelvis on the sacrum
    counts = dict(zip(*np.unique(np.asarray(rig.link_body), return_counts=True)))
    assert counts == {"torso": 13, "lumbar2": 2, "lumbar4": 2, "lumbar5": 2, "sacrum": 6}
    assert all(mjm.site(int(s)).name.startswith("membrane_hybrid_link_") for s in rig.site_id)
    assert mjm.nu == 210 and mjm.njnt == 18  # myotorso's muscles and joints, as packaged
    assert np.all(d.ctrl == 0.0)
    torso = mjm.body("torso").id
    x0 = d.xpos[torso].copy()
    for k in range(10):
        sim.step(100)
        pos = sim.state.vert_pos
        assert np.all(np.isfinite(pos)) and np.all(np.isfinite(d.qpos))
        assert sim.volume_rel_error <= 1e-10, (k, sim.volume_rel_error)
        # the linked points are on their sites, and the sites on their bodies
        np.testing.assert_array_equal(pos[rig.link_vert], d.site_xpos[rig.site_id])
        for j, s in enumerate(rig.site_id):
            b = mjm.site_bodyid[s]
            local = mjm.site_pos[s]
            np.testing.assert_allclose(d.xpos[b] + d.xmat[b].reshape(3, 3) @ local, pos[rig.link_vert[j]],
                                       atol=1e-12)
        assert np.abs(pos - pos.mean(axis=0)).max() < 0.5  # no runaway point
    assert d.time == pytest.approx(1.0)
    # zero muscle control: the thorax slumps forward and the membrane comes along
    assert np.linalg.norm(d.xpos[torso] - x0) > 0.01
    assert mujoco.mj_name2id(mjm, mujoco.mjtObj.mjOBJ_BODY, "sacrum") >= 0
    assert _package_hash() == before


def test_missing_package_is_named_with_the_extra(monkeypatch):
    import sys
    from hybrid.scenefile import load_scene
    from hybrid.model import compile_scene
    monkeypatch.setitem(sys.modules, "myo_sim", None)  # import myo_sim raises ImportError
    with pytest.raises(RigidError, match=r"myo_sim.*not installed.*hybrid\[myo\]"):
        compile_scene(load_scene(SCENE))
