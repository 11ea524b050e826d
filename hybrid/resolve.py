"""From what a user names to a `Scene`: the one resolver behind `hybrid.load`,
`hybrid run`, `render`, `view` and the studies.

A source is a `Scene` (taken as it is), a path to a TOML scene file (`*.toml`),
a packaged scene file by name ("breathing", "myotorso_breathing") or a scene
written in Python by name ("membrane_demo", `hybrid.demo`). `--set KEY=VALUE`
overrides (`hybrid.scenefile.apply_overrides`) and removed terms (`--without
NAME`, `Scene.without`) apply to any of them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from . import scenefile
from .demo import breathing_lungs, membrane_demo
from .errors import SceneError
from .scene import Scene

__all__ = ["DEFAULT_SCENE", "PYTHON_SCENES", "scene_names", "resolve_scene"]

DEFAULT_SCENE = "breathing"

#: the scenes written in Python, by name: each a function returning a `Scene`
PYTHON_SCENES: dict[str, Callable[[], Scene]] = {"membrane_demo": membrane_demo, "breathing_lungs": breathing_lungs}


def scene_names() -> list[str]:
    """Every scene a name may stand for: the packaged scene files and `PYTHON_SCENES`."""
    return sorted(set(scenefile.builtin_scenes()) | set(PYTHON_SCENES))


def _named(source: str | Path) -> Scene:
    text = str(source)
    if text.endswith(".toml"):
        return scenefile.load_scene(Path(text))
    if text in PYTHON_SCENES:
        return PYTHON_SCENES[text]()
    if text in scenefile.builtin_scenes():
        return scenefile.load_scene(scenefile.builtin_scene(text))
    raise SceneError(f"scene {text!r}: no such scene; expected a .toml file or one of: {', '.join(scene_names())}")


def resolve_scene(
    source: str | Path | Scene | None = None, *, overrides: Sequence[str] = (), without: Sequence[str] = ()
) -> Scene:
    """The `Scene` that `source` names (None: the packaged breathing trunk), with
    `overrides` ("KEY=VALUE" strings) applied, then the terms named in `without`
    removed. Raises SceneError, one line: an unknown name (listing the valid ones),
    a missing or invalid file, a bad override, an unknown term."""
    if isinstance(source, Scene):
        scene = source
    elif isinstance(source, (str, Path)) or source is None:
        scene = _named(DEFAULT_SCENE if source is None else source)
    else:
        raise SceneError(
            f"scene: expected a Scene, a .toml path or one of {scene_names()}, received {type(source).__name__}"
        )
    overrides, without = _strings("overrides", overrides, "KEY=VALUE"), _strings("without", without, "NAME")
    if overrides:
        scene = scenefile.apply_overrides(scene, list(overrides))
    if without:
        scene = scene.without(*without)
    return scene


def _strings(name: str, value, form: str) -> tuple:
    """A list of strings as given: a string alone is refused, not split into characters."""
    if isinstance(value, (str, bytes)):
        raise SceneError(
            f"{name}: expected a list of {form} strings, received the string {value!r:.80}; put it in a list"
        )
    try:
        items = tuple(value)
    except TypeError:
        raise SceneError(f"{name}: expected a list of {form} strings, received {type(value).__name__}") from None
    bad = [v for v in items if not isinstance(v, str)]
    if bad:
        raise SceneError(f"{name}: expected a list of {form} strings, received an item {bad[0]!r:.80}")
    return items
