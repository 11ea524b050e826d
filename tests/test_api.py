"""The public API for scripted experiments: hybrid.load and repeated runs."""

import ast
import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import hybrid


def test_load_builtin_breathing_exposes_state_and_mujoco():
    sim = hybrid.load("breathing_paper")
    assert sim.mj_model is not None and sim.mj_data is not None
    z_rib0 = sim.mj_data.site_xpos.copy()
    sim.step(800)  # 0.8 s into the first inspiration
    assert sim.time == pytest.approx(0.8)
    assert sim.vert_pos.shape == (80, 3)
    assert abs(sim.volume - sim.model.arrays.vol0) <= 1e-12 * sim.model.arrays.vol0
    assert sim.pressure > 0  # the contracting diaphragm pressurises the abdomen
    assert not np.array_equal(sim.mj_data.site_xpos, z_rib0)  # the ribs moved


def test_parameters_change_and_the_run_repeats(tmp_path):
    scene = hybrid.load_scene("breathing_paper")
    runs = {}
    for dt in (1e-3, 5e-4):
        sim = hybrid.load(dataclasses.replace(scene, dt_s=dt))
        sim.step(int(round(0.5 / dt)))
        runs[dt] = sim.pressure
    # same physics at two steps: the pressures agree to the integrator's O(h) error
    assert runs[1e-3] == pytest.approx(runs[5e-4], rel=0.05)
    assert runs[1e-3] != runs[5e-4]


def test_membrane_only_scene_has_no_mujoco():
    from hybrid.demo import membrane_demo

    sim = hybrid.load(membrane_demo())
    assert sim.mj_model is None and sim.mj_data is None


def test_load_scene_takes_every_name_the_command_line_takes():
    assert hybrid.load_scene("membrane_demo").name == "membrane_demo"
    assert hybrid.load("membrane_demo").mj_model is None
    scene = hybrid.load_scene("membrane_demo", overrides=["dt_s=5e-4"], without=["muscle"])
    assert scene.dt_s == 5e-4 and "muscle" not in scene.term_names()
    with pytest.raises(
        hybrid.SceneError, match="'snoring'.*breathing, breathing_lungs, breathing_paper, membrane_demo"
    ):
        hybrid.load("snoring")
    assert {"breathing", "membrane_demo", "myotorso_breathing"} <= set(hybrid.scene_names())


def test_every_public_name_resolves_and_is_listed_once():
    assert len(hybrid.__all__) == len(set(hybrid.__all__))
    for name in hybrid.__all__:
        assert getattr(hybrid, name) is not None, name
    # the vocabulary of a scene: every term, region selector and schedule
    from hybrid import regions, scene, schedule

    vocabulary = (
        set(scene.__all__) - {"INTEGRATORS", "FORMULATIONS"}
        | set(regions.__all__) - {"Selector", "select", "contains", "select_faces"}
        | set(schedule.__all__) - {"Schedule", "as_schedule", "ScheduleTable", "stack_schedules", "schedule_eval"}
    )
    assert vocabulary <= set(hybrid.__all__)
    assert callable(hybrid.run) and callable(hybrid.sweep) and callable(hybrid.read)
    with pytest.raises(AttributeError, match="no attribute 'nosuchname'"):
        hybrid.nosuchname  # noqa: B018 (the attribute access is the test)


def test_import_hybrid_loads_no_optional_part():
    code = (
        "import sys, hybrid; heavy = ('matplotlib', 'mujoco', 'mcap', 'dask', 'hybrid.record', "
        "'hybrid.cli'); print([m for m in heavy if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300)
    assert out.stdout.strip() == "[]", out.stdout


def _imported_modules(package: Path, path: Path):
    """The absolute names of the modules an `import` in `path` may load."""
    here = ["hybrid", *path.relative_to(package).parent.parts]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = here[: len(here) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            yield module
            yield from (f"{module}.{a.name}" for a in node.names)


def test_only_the_entry_point_imports_the_command_line():
    package = Path(hybrid.__file__).parent
    importers = sorted(
        str(p.relative_to(package)) for p in package.rglob("*.py") if "hybrid.cli" in set(_imported_modules(package, p))
    )
    assert importers == ["__main__.py"]


def _readme_python_example() -> str:
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## Using it") :]
    section = section[: section.index("\n## ", 1)]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert len(blocks) == 1, "the section 'Using it' holds one Python example"
    return blocks[0]


def test_the_readme_example_imports_only_hybrid_and_runs(capsys):
    code = _readme_python_example()
    tree = ast.parse(code)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            assert [a.name for a in node.names] == ["hybrid"], ast.unparse(node)
        elif isinstance(node, ast.ImportFrom):
            assert node.module == "hybrid" and node.level == 0, ast.unparse(node)
    exec(compile(tree, "README.md", "exec"), {"__name__": "readme"})
    printed = capsys.readouterr().out.split()
    time_s, vol_err, _, run_vol_err, apex_mm = map(float, printed)
    assert time_s == pytest.approx(1.0) and vol_err <= 1e-12 and run_vol_err <= 1e-12 and apex_mm > 0
