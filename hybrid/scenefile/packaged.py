"""The packaged models and scene files (the repository's models/, installed as `hybrid.models`)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from ..errors import SceneError

__all__ = ["packaged_model", "builtin_scenes", "builtin_scene"]


def packaged_model(relative: str) -> Path:
    """The path of a file of the packaged models (MJCF, scene TOMLs): the repository's
    `models/` folder, installed as the package `hybrid.models` (see pyproject.toml).
    A source tree put on sys.path without installing has no `hybrid.models`: there
    the folder is read beside the package."""
    try:
        root = Path(str(resources.files("hybrid.models")))
    except ModuleNotFoundError:
        root = Path(__file__).resolve().parents[2] / "models"
    return root / relative


def builtin_scenes() -> list[str]:
    """Names of the packaged scene files (models/scenes)."""
    return sorted(p.stem for p in packaged_model("scenes").glob("*.toml"))


def builtin_scene(name: str = "breathing") -> Path:
    """The path of a packaged scene file (default: the breathing trunk of figure 4)."""
    path = packaged_model("scenes") / f"{name}.toml"
    if not path.is_file():
        raise SceneError(f"built-in scene {name!r}: no such scene; available: {builtin_scenes()}")
    return path
