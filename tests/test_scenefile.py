"""Scene files (TOML): the same fields as the dataclasses, strict one-line errors, overrides.

Every malformed file in tests/data/bad_scenes/ says in its header what its error
must name (`# expect: a | b | c`, all of them) and its class (`# error: SceneError`).
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from hybrid import errors
from hybrid import regions as R
from hybrid import scenefile as sf
from hybrid.errors import HybridError, SceneError
from hybrid.model import compile_scene
from hybrid.schedule import Breathing, Constant, Table

HERE = Path(__file__).resolve().parent
BAD = sorted((HERE / "data" / "bad_scenes").glob("*.toml"))


def header(path: Path) -> tuple[list[str], str]:
    expect, cls = [], ""
    for line in path.read_text().splitlines():
        if line.startswith("# expect:"):
            expect = [s.strip() for s in line.split(":", 1)[1].split(" | ")]
        elif line.startswith("# error:"):
            cls = line.split(":", 1)[1].strip()
    return expect, cls


def test_there_are_at_least_twelve_bad_scenes():
    assert len(BAD) >= 12
    for path in BAD:
        expect, cls = header(path)
        assert expect and hasattr(errors, cls), path.name


@pytest.mark.parametrize("path", BAD, ids=[p.stem for p in BAD])
def test_bad_scene_gives_one_line_naming_the_culprit(path):
    expect, cls = header(path)
    with pytest.raises(HybridError) as err:
        compile_scene(sf.load_scene(path))
    assert type(err.value).__name__ == cls, err.value
    msg = str(err.value)
    assert "\n" not in msg
    for piece in expect:
        assert piece in msg, (piece, msg)


def test_bad_scenes_exit_with_status_2_and_one_stderr_line(tmp_path, capsys):
    cli = pytest.importorskip("hybrid.cli")
    for path in BAD:
        assert cli.main(["run", str(path), "--out", str(tmp_path / path.stem)]) == 2, path.name
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1, (path.name, err)
        assert header(path)[0][0] in err, (path.name, err)
    # once in a fresh process, as a user would run it
    path = HERE / "data" / "bad_scenes" / "bad_scene_negative_stiffness.toml"
    proc = subprocess.run(
        [sys.executable, "-m", "hybrid.cli", "run", str(path), "--out", str(tmp_path / "p")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "hybrid: error: bad_scene_negative_stiffness.toml: forces[2].stiffness_n_per_m: "
        "expected a number > 0, received -3"
    ]


def test_missing_scene_file_names_it(tmp_path):
    with pytest.raises(SceneError, match="nope.toml.*no such file"):
        sf.load_scene(tmp_path / "nope.toml")


# ----------------------------------------------------------------- same fields as the dataclasses


@pytest.mark.parametrize("table", ["FORCE_TYPES", "CONSTRAINT_TYPES"])
def test_every_term_field_has_a_kind_the_reader_knows(table):
    """The TOML keys of a term are its dataclass fields (hybrid.terms.base): each
    needs a kind that says how the file spells and checks it."""
    from hybrid.terms import base

    types = getattr(sf, table)
    assert types, table
    for typ, cls in types.items():
        assert cls.toml_type == typ
        for name, f in cls.fields().items():
            kind = f.metadata.get("kind")
            assert kind in (*base.VALUE_KINDS, "selector", "schedule"), (typ, name, kind)
            if kind == "schedule":
                assert f.metadata["ncomp"] in (1, 3), (typ, name)


def test_every_scene_field_is_a_toml_key():
    from hybrid.scene import Scene

    fields = {f.name for f in dataclasses.fields(Scene)} - {"base_dir"}
    assert fields == set(sf._TOP)
    assert set(sf.scene_to_dict(sf.load_scene(sf.builtin_scene()))) == fields


def test_breathing_scene_round_trips_through_a_mapping():
    scene = sf.load_scene(sf.builtin_scene())
    assert scene.name == "breathing" and Path(scene.base_dir) == sf.builtin_scene().parent
    again = sf.scene_from_dict(sf.scene_to_dict(scene), source="x", base_dir=scene.base_dir)
    assert again == scene


def test_every_selector_and_schedule_form(tmp_path):
    text = textwrap.dedent("""\
        formulation = "paper"
        [mesh]
        generator = "uv_sphere"
        [masses]
        density_kg_per_m2 = { all = 20.0 }
        [regions]
        top = { half_space = { point = [0, 0, 0.07], normal = [0, 0, 1] } }
        apex = { indices = [0] }
        ball = { ball = { center = [0, 0, -0.12], radius = 0.05 } }
        box = { box = { lo = [-1, -1, -0.03], hi = [1, 1, 0.03] } }
        near = { nearest = [[0.12, 0, 0], [-0.12, 0, 0]] }
        both = { union = ["apex", "ball"] }
        mid_top = { intersection = ["top", { box = { lo = [-1, -1, 0.1], hi = [1, 1, 0.115] } }] }
        rest = { difference = { base = "all", minus = "top" } }
        alias = "top"
        [[forces]]
        type = "muscle"
        region = "top"
        axis = [0, 0, 1]
        stiffness = { table = { t_s = [0, 1, 2], value = [0, 50, 0], periodic = true } }
        [[forces]]
        type = "applied_force"
        region = "apex"
        force_n = { table = { t_s = [0, 1], value = [[0, 0, 0], [0, 0, -1]] } }
        [[forces]]
        type = "attraction"
        region = "near"
        stiffness_n_per_m = 10.0
        offset_m = [0, 0, 0.001]
        [[constraints]]
        type = "keep_in"
        region = "box"
        shape = "ball"
        center_m = [0, 0, 0]
        radius_m = 0.2
        [[constraints]]
        type = "prescribed"
        region = "ball"
        displacement_m = [0, 0, 0]
        """)
    path = tmp_path / "all.toml"
    path.write_text(text)
    scene = sf.load_scene(path)
    assert scene.regions["both"] == R.Union_(("apex", "ball"))
    assert scene.regions["ball"] == R.Ball((0.0, 0.0, -0.12), 0.05)
    assert scene.forces[0].stiffness == Table((0.0, 1.0, 2.0), (0.0, 50.0, 0.0), True)
    assert scene.forces[2].offset_m == Constant((0.0, 0.0, 0.001))
    model = compile_scene(scene)
    pos = model.mesh.vert_pos
    assert model.regions["apex"].tolist() == [0]
    assert np.all(pos[model.regions["top"], 2] >= 0.07)
    np.testing.assert_array_equal(model.regions["alias"], model.regions["top"])
    assert model.regions["rest"].size + model.regions["top"].size == model.nvert
    assert model.regions["near"].size == 2 and model.regions["mid_top"].size == 13
    assert set(model.terms) == {"muscle", "applied_force", "attraction", "keep_in", "prescribed"}
    again = sf.scene_from_dict(sf.scene_to_dict(scene), source="x", base_dir=scene.base_dir)
    assert again == scene


def test_a_mesh_file_resolves_in_the_scene_files_folder(tmp_path, monkeypatch):
    import trimesh

    folder = tmp_path / "scenes"
    folder.mkdir()
    trimesh.creation.icosphere(subdivisions=1, radius=0.1).export(folder / "ball.obj")
    (folder / "ball.toml").write_text(
        '[mesh]\npath = "ball.obj"\n[masses]\ntotal_kg = 1.0\n[[constraints]]\ntype = "volume"\n'
    )
    monkeypatch.chdir(tmp_path)
    model = compile_scene(sf.load_scene("scenes/ball.toml"))
    assert model.nvert == 42


# ----------------------------------------------------------------- overrides


def test_overrides_follow_dotted_paths_through_named_terms():
    scene = sf.load_scene(sf.builtin_scene("breathing_paper"))
    new = sf.apply_overrides(
        scene,
        [
            "dt_s=5e-4",
            "forces.muscle.stiffness.breathing.peak=80",
            "forces.4.critical_fraction=0.5",
            "integrator=explicit_euler",
            "rigid.links.rib_left.body=rib_left_attach",
            "mesh.radius_m = 0.11",
        ],
    )
    assert new.dt_s == 5e-4 and new.integrator == "explicit_euler" and new.mesh.radius_m == 0.11
    assert new.forces[2].stiffness == Breathing(4.0, 0.4, 80.0)
    assert new.forces[4].critical_fraction == 0.5
    assert new.rigid.links[0].body == "rib_left_attach"
    assert scene.dt_s == 1e-3  # the original is untouched
    assert sf.apply_overrides(scene, []) == scene


@pytest.mark.parametrize(
    "item, culprit",
    [
        ("dt_s", "expected KEY=VALUE"),
        ("forces.nomuscle.stiffness=3", "no element named 'nomuscle'"),
        ("forces.9.stiffness=3", "no index 9"),
        ("mesh.radius=0.1", "mesh.radius: unknown key"),
        ("dt_s=-1", "dt_s: expected a number > 0, received -1"),
        ("forces.muscle.stiffness.breathing.peak=high", "forces[2].stiffness.breathing.peak"),
        ("regions.nowhere.half_space.point=[0, 0, 0]", "no key 'nowhere'"),
    ],
)
def test_bad_overrides_name_the_culprit(item, culprit):
    scene = sf.load_scene(sf.builtin_scene("breathing_paper"))
    with pytest.raises(SceneError) as err:
        sf.apply_overrides(scene, [item])
    assert culprit in str(err.value) and "\n" not in str(err.value)


def test_builtin_scene_names():
    assert "breathing" in sf.builtin_scenes()
    with pytest.raises(SceneError, match="no such scene.*breathing"):
        sf.builtin_scene("snoring")
