"""The packaged scene `myotorso_breathing` is the trunk `hybrid anatomy` fits to myo-sim's torso
now (`hybrid.anatomy.packaged`): a change of the fit that is not written into the package fails
here, naming the command that writes it."""

import importlib.util

import numpy as np
import pytest

from hybrid.anatomy.packaged import NAME, RUN, packaged_scene
from hybrid.mesh.obj import read_obj
from hybrid.scenefile import builtin_scene, load_scene, scene_to_toml

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("myo_sim") is None,
    reason="myo_sim (PyPI myo-sim) is not installed: pip install -e '.[myo]'",
)

AGAIN = "write it again: python -m hybrid.anatomy.packaged models/scenes"


def test_the_packaged_torso_is_the_fit_of_today(tmp_path):
    fitted = packaged_scene(tmp_path)
    path = builtin_scene(NAME)
    packaged = load_scene(path)
    assert scene_to_toml(packaged) == scene_to_toml(fitted), AGAIN
    # its membrane: the fit's points and triangles (the file's text is numpy's, the same bits)
    ours, theirs = read_obj(path.parent / packaged.mesh.path), read_obj(tmp_path / "abdomen.obj")
    np.testing.assert_array_equal(ours[1], theirs[1], err_msg=AGAIN)
    np.testing.assert_allclose(ours[0], theirs[0], rtol=0, atol=1e-12, err_msg=AGAIN)
    assert (packaged.integrator, packaged.dt_s, packaged.duration_s) == tuple(RUN.values())
    # the header says where each parameter comes from: the fitted figures it quotes are today's
    text = path.read_text()
    x, f = ours
    litres = 1e3 * np.einsum("ij,ij->i", x[f[:, 0]], np.cross(x[f[:, 1]], x[f[:, 2]])).sum() / 6.0
    assert f"{len(x):,} points" in text and f"Abdomen {litres:.2f} L" in text
    assert "calibration, not validation" in text
