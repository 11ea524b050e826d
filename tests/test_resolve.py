"""hybrid.resolve: one way from a name, a path or a Scene to a Scene."""

import dataclasses
import shutil

import pytest

from hybrid import scenefile
from hybrid.demo import membrane_demo
from hybrid.errors import SceneError
from hybrid.resolve import resolve_scene, scene_names


def test_every_kind_of_source_resolves(tmp_path):
    assert resolve_scene().name == "breathing"
    assert resolve_scene("breathing") == scenefile.load_scene(scenefile.builtin_scene("breathing"))
    assert resolve_scene("membrane_demo") == membrane_demo()
    path = tmp_path / "copy.toml"
    shutil.copy(scenefile.builtin_scene("breathing"), path)
    assert resolve_scene(str(path)).name == "breathing"
    assert resolve_scene(path).name == "breathing"
    scene = membrane_demo()
    assert resolve_scene(scene) is scene


def test_the_names_are_the_packaged_scenes_and_the_python_ones():
    assert set(scene_names()) == set(scenefile.builtin_scenes()) | {"membrane_demo", "breathing_lungs"}
    assert {"breathing", "myotorso_breathing", "membrane_demo"} <= set(scene_names())


def test_an_unknown_name_is_refused_in_one_line_listing_the_valid_ones():
    with pytest.raises(SceneError) as err:
        resolve_scene("snoring")
    msg = str(err.value)
    assert "\n" not in msg and "'snoring'" in msg
    for name in scene_names():
        assert name in msg
    with pytest.raises(SceneError, match="received int"):
        resolve_scene(3)


def test_a_missing_toml_file_is_named(tmp_path):
    with pytest.raises(SceneError, match="nope.toml.*no such file"):
        resolve_scene(str(tmp_path / "nope.toml"))


def test_overrides_and_removed_terms_apply_to_any_source():
    for source in ("breathing", "membrane_demo", membrane_demo()):
        scene = resolve_scene(source, overrides=["dt_s=5e-4"], without=["damping"])
        assert scene.dt_s == 5e-4
        assert "damping" not in scene.term_names() and "damping" in resolve_scene(source).term_names()
    changed = resolve_scene("membrane_demo", overrides=["forces.shape_memory.stiffness_n_per_m=100"])
    assert changed == dataclasses.replace(
        membrane_demo(),
        forces=tuple(
            dataclasses.replace(f, stiffness_n_per_m=100.0) if f.name == "shape_memory" else f
            for f in membrane_demo().forces
        ),
    )
    with pytest.raises(SceneError, match="nosuchterm"):
        resolve_scene("membrane_demo", without=["nosuchterm"])
    with pytest.raises(SceneError, match="expected KEY=VALUE"):
        resolve_scene("membrane_demo", overrides=["dt_s"])
