"""Scene.formulation: "paper" keeps the per-point model of Promayon et al. 1997;
"continuum" (the default) takes only material parameters, and refuses per-point ones
and single-point regions with one line naming them."""

import pytest

import hybrid
from hybrid import Damping, Gravity, Masses, MeshSpec, Nailed, Nearest, Scene, ShapeMemory, Volume
from hybrid.errors import SceneError

SPHERE = MeshSpec(generator="icosphere", subdivisions=1, radius_m=0.1)


def test_the_default_formulation_is_continuum_and_every_packaged_scene_says_which():
    assert Scene().formulation == "continuum"
    for name in hybrid.scenefile.builtin_scenes():
        text = hybrid.scenefile.builtin_scene(name).read_text()
        assert "\nformulation = " in text, name


def test_a_paper_term_in_a_continuum_scene_is_refused_naming_it():
    scene = Scene(mesh=SPHERE, masses=Masses(total_kg=1.0), forces=(ShapeMemory(100.0),))
    with pytest.raises(
        SceneError,
        match=r"forces\['shape_memory'\]: type 'shape_memory' belongs to "
        r"formulation 'paper'.*formulation = 'paper'",
    ):
        hybrid.compile_scene(scene)
    hybrid.compile_scene(
        Scene(formulation="paper", mesh=SPHERE, masses=Masses(total_kg=1.0), forces=(ShapeMemory(100.0),))
    )


def test_a_per_point_field_of_a_shared_term_is_refused_in_a_continuum_scene():
    scene = Scene(mesh=SPHERE, masses=Masses(total_kg=1.0), forces=(Gravity(), Damping(coef_n_s_per_m=1.0)))
    with pytest.raises(
        SceneError,
        match=r"forces\['damping'\]\.coef_n_s_per_m: a parameter of formulation "
        r"'paper'",
    ):
        hybrid.compile_scene(scene)


def test_a_single_point_region_is_refused_in_a_continuum_scene():
    scene = Scene(
        mesh=SPHERE,
        masses=Masses(total_kg=1.0),
        regions={"pin": Nearest(((0.0, 0.0, -0.1),))},
        constraints=(Nailed("pin"), Volume()),
    )
    with pytest.raises(SceneError, match=r"regions\.pin: a `nearest` selector picks single points"):
        hybrid.compile_scene(scene)
    hybrid.compile_scene(__import__("dataclasses").replace(scene, formulation="paper"))


def test_a_scene_file_with_an_unknown_formulation_is_one_line(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('formulation = "fem"\n[mesh]\ngenerator = "icosahedron"\n[masses]\ntotal_kg = 1.0\n')
    with pytest.raises(
        SceneError,
        match=r"formulation: expected one of \['continuum', 'paper'\], "
        r"received 'fem'",
    ):
        hybrid.load_scene(p)
