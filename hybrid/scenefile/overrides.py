"""`--set KEY=VALUE`: a scene changed by dotted paths in its TOML structure."""

from __future__ import annotations

import copy
import tomllib

from .. import regions as R
from ..errors import SceneError
from ..scene import Scene
from .read import scene_from_dict
from .write import scene_to_dict

__all__ = ["apply_overrides"]


def _parse_value(text: str):
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError as exc:
        if any(c in text for c in "\"'[]{}"):  # meant as TOML, but malformed: not a word
            raise SceneError(
                f'--set value {text[:80]!r}: expected a TOML value (a number, "a string", [a, list], '
                f"{{a = table}}) or a bare word, received one that does not parse ({exc})"
            ) from None
        return text.strip()  # a bare word: a string
    except RecursionError:  # the TOML reader recurses once per nested table or list
        raise SceneError(
            f"--set value {text[:40]!r}...: tables or lists nested too deep to read; expected "
            f"selectors at most {R.MAX_SELECTOR_DEPTH} levels deep"
        ) from None


def apply_overrides(scene: Scene, overrides) -> Scene:
    """A copy of `scene` with `KEY=VALUE` overrides applied (module docstring).

    Raises SceneError naming the override for a malformed item or a path that does
    not exist, and the usual one-line SceneError if the result is not a valid scene.
    """
    d = copy.deepcopy(scene_to_dict(scene))
    for item in overrides:
        if not isinstance(item, str) or "=" not in item:
            raise SceneError(f"--set {item!r}: expected KEY=VALUE, e.g. dt_s=5e-4")
        key, text = item.split("=", 1)
        key = key.strip()
        parts = key.split(".")
        if not key or not all(parts):
            raise SceneError(f"--set {item!r}: expected a dotted key such as forces.muscle.stiffness")
        node = d
        for depth, part in enumerate(parts[:-1]):
            node = _descend(node, part, item, ".".join(parts[:depth]))
        last = parts[-1]
        if isinstance(node, list):
            idx = _list_index(node, last, item, ".".join(parts[:-1]))
            node[idx] = _parse_value(text)
        elif isinstance(node, dict):
            node[last] = _parse_value(text)
            if parts[0] == "mesh" and len(parts) == 2 and last in _MESH_SOURCES:
                # a mesh file replaces the scene's generator, a generator its file
                node.pop(_MESH_SOURCES[last], None)
        else:
            raise SceneError(f"--set {item!r}: {'.'.join(parts[:-1])} is a value, not a table")
    return scene_from_dict(d, source=f"{scene.name} (with --set)", base_dir=scene.base_dir)


#: the two sources of a mesh, each the other's alternative
_MESH_SOURCES = {"path": "generator", "generator": "path"}


def _descend(node, part, item, where):
    if isinstance(node, dict):
        if part not in node:
            # an absent sub-table of an existing table (e.g. mesh.* keys are always present)
            raise SceneError(f"--set {item!r}: no key {part!r} in {where or 'the scene'}; keys there: {sorted(node)}")
        return node[part]
    if isinstance(node, list):
        return node[_list_index(node, part, item, where)]
    raise SceneError(f"--set {item!r}: {where} is a value, not a table")


def _list_index(node, part, item, where):
    if part.isdigit():
        idx = int(part)
        if idx >= len(node):
            raise SceneError(f"--set {item!r}: {where} has {len(node)} elements, no index {idx}")
        return idx
    names = [x.get("name", x.get("type")) if isinstance(x, dict) else None for x in node]
    if part not in names:
        raise SceneError(f"--set {item!r}: no element named {part!r} in {where}; names: {names}")
    return names.index(part)
