"""What an installed hybrid holds: models/ (the one copy of the MJCF and scene files)
becomes the package hybrid.models, and the built-in scenes and the trunk resolve
there, not by walking up to a repository."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SETUPTOOLS = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]


def _package_folder(package: str) -> Path:
    """The repository folder of a package, as setuptools maps it (package-dir, else its name)."""
    mapping = SETUPTOOLS.get("package-dir", {})
    parts = package.split(".")
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in mapping:
            return REPO / mapping[".".join(parts[:n])] / Path(*parts[n:])
    return REPO / Path(*parts)


def _install_like_a_wheel(site: Path) -> None:
    """Lay out what the wheel holds under site: each package's modules and package data."""
    for package in SETUPTOOLS["packages"]:
        source, target = _package_folder(package), site / Path(*package.split("."))
        target.mkdir(parents=True, exist_ok=True)
        files = list(source.glob("*.py"))
        for pattern in SETUPTOOLS.get("package-data", {}).get(package, []):
            files += source.glob(pattern)
        for f in files:
            shutil.copy2(f, target / f.relative_to(source))


def test_pyproject_names_every_package_and_every_model_file():
    packages = set(SETUPTOOLS["packages"])
    in_tree = {
        ".".join(("hybrid", *p.parent.relative_to(REPO / "hybrid").parts))
        for p in (REPO / "hybrid").rglob("__init__.py")
    }
    # every folder of models/ is a package of the wheel (its data files need one)
    models = {
        ".".join(("hybrid", "models", *d.relative_to(REPO / "models").parts))
        for d in [REPO / "models", *(REPO / "models").rglob("*")]
        if d.is_dir() and d.name != "__pycache__"
    }
    assert packages == in_tree | models
    data = SETUPTOOLS["package-data"]
    for f in (REPO / "models").rglob("*"):
        if f.is_file() and f.suffix not in (".py", ".pyc"):
            package = ".".join(("hybrid", *f.parent.relative_to(REPO).parts))
            assert any(f.match(pattern) for pattern in data.get(package, [])), f"{f} is not package data"


def test_builtin_scenes_and_trunk_resolve_inside_the_installed_package(tmp_path):
    site = tmp_path / "site"
    _install_like_a_wheel(site)
    assert not (site / "models").exists()  # nothing to find beside the package
    code = (
        "import hybrid.scenefile as s, hybrid.rigid as r; "
        "print(s.builtin_scenes()); print(s.builtin_scene('breathing')); "
        "print(s.builtin_scene('myotorso_breathing')); print(r.TRUNK_XML)"
    )
    env = {**os.environ, "PYTHONPATH": str(site), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path, check=True
    ).stdout.splitlines()
    assert out[0] == "['breathing', 'breathing_paper', 'myotorso_breathing']"
    models = site / "hybrid" / "models"
    for line, expected in zip(out[1:], ("scenes/breathing.toml", "scenes/myotorso_breathing.toml", "trunk.xml")):
        assert Path(line) == models / expected and Path(line).is_file()
        assert Path(line).read_bytes() == (REPO / "models" / expected).read_bytes()
    # the fitted torso's membrane, which its scene file names beside it
    mesh = models / "scenes" / "myotorso_breathing" / "abdomen.obj"
    assert mesh.read_bytes() == (REPO / "models" / "scenes" / "myotorso_breathing" / "abdomen.obj").read_bytes()


def test_the_version_has_one_place_and_the_command_prints_it():
    import hybrid

    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    assert "version" not in project and "version" in project["dynamic"]  # not typed a second time
    assert SETUPTOOLS["dynamic"]["version"] == {"attr": "hybrid.__version__"}
    from importlib import metadata

    # what pip installed read the same place (after a bump, `pip install -e .` again)
    assert metadata.version(project["name"]) == hybrid.__version__
    out = subprocess.run([sys.executable, "-m", "hybrid", "--version"], capture_output=True, text=True, cwd=REPO)
    assert (out.returncode, out.stdout.strip()) == (0, f"hybrid {hybrid.__version__}")


def test_the_distribution_and_its_commands():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    # "hybrid" on the package registry is another project (a web tool set, 1.2.3)
    assert project["name"] == "hybrid-trunk"
    # the command named after the distribution (`pipx run hybrid-trunk`) and the import package's
    assert project["scripts"] == {"hybrid": "hybrid.cli:main", "hybrid-trunk": "hybrid.cli:main"}
