"""Pictures that show the membrane: the MJCF model's wrapping, collision and helper
geoms (MuJoCo geom groups 3 and above, or transparent) are left out of `hybrid
render` and hidden in `hybrid view`, and the membrane is drawn over the bones."""

from __future__ import annotations

import importlib.util

import mujoco
import numpy as np
import pytest

from hybrid.cli import main
from hybrid.record import body_geoms
from hybrid.render import SHOWN_GEOM_GROUPS, draw_figure, frames_from_recording, key_frames, shown_geoms
from hybrid.rigid import show_geom_groups

_MJCF = """
<mujoco>
  <worldbody>
    <body name="rib" pos="0 0 1">
      <geom name="bone" type="capsule" size="0.01 0.05" rgba="0.8 0.7 0.6 1"/>
      <geom name="collision" type="capsule" size="0.02 0.05" group="3" rgba="0.5 0.5 0.5 1"/>
      <geom name="wrap" type="sphere" size="0.03" group="1" rgba="0 0 1 0"/>
      <geom name="helper" type="cylinder" size="0.03 0.01" group="5" rgba="1 0 0 0.5"/>
    </body>
  </worldbody>
</mujoco>
"""


def test_geom_group_filter_keeps_the_visible_bones_only():
    m = mujoco.MjModel.from_xml_string(_MJCF)
    geoms = body_geoms(m)
    assert [g["group"] for g in geoms] == [0, 3, 1, 5]
    assert [g["name"] for g in shown_geoms(geoms)] == ["bone"]
    # an older recording's geoms carry no group: drawn as group 0
    old = [{k: v for k, v in g.items() if k != "group"} for g in geoms]
    assert [g["name"] for g in shown_geoms(old)] == ["bone", "collision", "helper"]
    # the viewer's option: groups 0-2 on, the rest off
    opt = mujoco.MjvOption()
    opt.geomgroup[:] = 1
    show_geom_groups(opt, SHOWN_GEOM_GROUPS)
    assert list(opt.geomgroup) == [1, 1, 1, 0, 0, 0]


def _image(path):
    import matplotlib.image as mpimg

    img = mpimg.imread(path)[..., :3]
    h = img.shape[0]
    return img[int(0.12 * h) : int(0.5 * h)]  # the 3D views, below the titles


@pytest.mark.skipif(
    importlib.util.find_spec("myo_sim") is None,
    reason="myo_sim (PyPI myo-sim) is not installed: pip install -e '.[myo]'",
)
def test_render_of_a_myotorso_recording_shows_the_membrane_in_every_panel(tmp_path, capsys):
    run_dir = tmp_path / "run"
    assert main(["run", "myotorso_breathing", "--duration", "0.3", "--out", str(run_dir)]) == 0
    out = tmp_path / "fig"
    assert main(["render", str(run_dir / "run.mcap"), "--out", str(out)]) == 0
    # 0.3 s is inside the first inspiration: no breath to name the panels after
    said = capsys.readouterr().out
    assert "largest displacement" in said and "inspiration" not in said
    fr = frames_from_recording(run_dir / "run.mcap")
    assert fr.geoms and all(g["group"] in SHOWN_GEOM_GROUPS for g in fr.geoms)
    img = _image(out / "figure4.png")
    draw_figure(fr, tmp_path / "bare.png", list(key_frames(fr)), membrane=False)
    bare = _image(tmp_path / "bare.png")
    w = img.shape[1] // 3
    for i in range(3):
        shown = np.abs(img[:, i * w : (i + 1) * w] - bare[:, i * w : (i + 1) * w]).max(axis=2) > 0.1
        assert shown.mean() > 0.2, f"panel {i}: {shown.mean():.4f} of its pixels are the membrane's"


def test_panels_are_named_after_a_breath_only_where_the_frames_hold_one():
    from hybrid.render import PANEL_TITLES, STILL_TITLES, Frames, breathes, panel_titles

    t = np.linspace(0.0, 4.0, 41)
    rise = np.minimum(t, 1.6)  # a run stopped during its first inspiration
    breath = np.where(t < 1.6, t, np.maximum(3.2 - t, 0.0))
    pos = np.zeros((len(t), 3, 3))
    for muscle, titles in ((rise, STILL_TITLES), (breath, PANEL_TITLES), (None, STILL_TITLES)):
        fr = Frames(scene="s", t=t, pos=pos, face_vert=np.array([[0, 1, 2]]), vert_rgba=np.ones((3, 4)), muscle=muscle)
        assert panel_titles(fr) == titles and breathes(fr) == (titles == PANEL_TITLES)
