"""A `Scene` back to its mapping and its TOML text (`load_scene` of which gives it back)."""

from __future__ import annotations

import re

from .. import regions as R
from .. import schedule as S
from ..errors import SceneError
from ..rigidfile import rigid_to_table
from ..scene import MeshSpec, Scene
from .read import _MESH, _is_num  # the reader's own names for MeshSpec's fields and a number

__all__ = ["scene_to_dict", "scene_to_toml"]


def _sel_to(sel):
    if isinstance(sel, str):
        return sel
    if isinstance(sel, R.All):
        return "all"
    if isinstance(sel, R.Border):
        return {"border": True}
    if isinstance(sel, R.Indices):
        return {"indices": [int(i) for i in sel.indices]}
    if isinstance(sel, R.HalfSpace):
        return {"half_space": {"point": list(sel.point), "normal": list(sel.normal)}}
    if isinstance(sel, R.Ball):
        return {"ball": {"center": list(sel.center), "radius": sel.radius}}
    if isinstance(sel, R.Box):
        return {"box": {"lo": list(sel.lo), "hi": list(sel.hi)}}
    if isinstance(sel, R.Wedge):
        return {"wedge": {"from_deg": sel.from_deg, "to_deg": sel.to_deg, "center": list(sel.center)}}
    if isinstance(sel, R.Nearest):
        return {"nearest": [list(p) for p in sel.points]}
    if isinstance(sel, R.Patch):
        return {"patch": {"center": list(sel.center), "radius_m": sel.radius_m}}
    if isinstance(sel, R.Union_):
        return {"union": [_sel_to(p) for p in sel.parts]}
    if isinstance(sel, R.Intersection):
        return {"intersection": [_sel_to(p) for p in sel.parts]}
    if isinstance(sel, R.Difference):
        return {"difference": {"base": _sel_to(sel.base), "minus": _sel_to(sel.minus)}}
    raise SceneError(f"selector {sel!r}: cannot be written as TOML")


def _sched_to(s, what):
    if isinstance(s, S.Constant):
        s = s.value
    if isinstance(s, (int, float)) and not isinstance(s, bool):
        return float(s)
    if isinstance(s, (tuple, list)) and len(s) == 3 and all(_is_num(x) for x in s):
        return [float(x) for x in s]
    if isinstance(s, S.Breathing):
        return {
            "breathing": {
                "period_s": s.period_s,
                "inspiration_fraction": s.inspiration_fraction,
                "peak": s.peak,
                "onset_s": s.onset_s,
            }
        }
    if isinstance(s, S.Table):
        return {
            "table": {
                "t_s": list(s.t_s),
                "value": [list(v) if isinstance(v, (tuple, list)) else v for v in s.value],
                "periodic": s.periodic,
            }
        }
    raise SceneError(f"{what}: a Python function schedule cannot be written as TOML; use a table")


def _value_to(v, what):
    if isinstance(v, (S.Constant, S.Breathing, S.Table, S.Function)) or callable(v):
        return _sched_to(v, what)
    if isinstance(v, tuple):
        return [_value_to(x, what) for x in v]
    return v


def _term_to(term, what):
    out = {"type": term.toml_type}
    for name, f in term.fields().items():
        v = getattr(term, name)
        if v is None:
            continue
        kind = f.metadata["kind"]
        if kind == "selector":
            out[name] = _sel_to(v)
        elif kind == "schedule":
            out[name] = _sched_to(v, f"{what}.{name}")
        else:
            out[name] = _value_to(v, f"{what}.{name}")
    return out


def scene_to_dict(scene: Scene) -> dict:
    """The TOML mapping of `scene` (inverse of `scene_from_dict`). Raises SceneError
    for what TOML cannot hold: a `Mesh` object instead of a `MeshSpec`, Python
    function schedules."""
    if not isinstance(scene.mesh, MeshSpec):
        raise SceneError("mesh: a hybrid.mesh.Mesh object cannot be written as TOML; use a MeshSpec")
    d: dict = {
        "name": scene.name,
        "formulation": scene.formulation,
        "dt_s": scene.dt_s,
        "integrator": scene.integrator,
        "implicit_tol": scene.implicit_tol,
        "implicit_max_iter": scene.implicit_max_iter,
        "duration_s": scene.duration_s,
        "max_speed_m_s": scene.max_speed_m_s,
    }
    if scene.dt_s is None:  # the MJCF's own (a rigid part) or the default
        del d["dt_s"]
    ms = scene.mesh
    mesh = {k: getattr(ms, k) for k in _MESH if getattr(ms, k) is not None}
    mesh["center_m"] = list(ms.center_m)
    if ms.path is not None:  # a file: the generators' keys not written where they are the defaults
        mesh.pop("generator", None)
        for k, f in _MESH.items():
            if k != "path" and k in mesh and getattr(ms, k) == f.default:
                del mesh[k]
    d["mesh"] = mesh
    m = scene.masses
    if m.total_kg is not None:
        d["masses"] = {"total_kg": m.total_kg}
    elif m.density_kg_per_m2 is not None:
        d["masses"] = {"density_kg_per_m2": dict(m.density_kg_per_m2)}
    else:
        d["masses"] = {"per_vertex_kg": list(m.per_vertex_kg or ())}
    d["regions"] = {k: _sel_to(v) for k, v in scene.regions.items()}
    d["forces"] = [_term_to(t, f"forces[{k}]") for k, t in enumerate(scene.forces)]
    d["constraints"] = [_term_to(c, f"constraints[{k}]") for k, c in enumerate(scene.constraints)]
    if scene.rigid is not None:
        d["rigid"] = rigid_to_table(scene.rigid, _sel_to, _sched_to)
    return d


def scene_to_toml(scene: Scene) -> str:
    """The scene file of `scene`: `load_scene` of it gives `scene` back (SceneError
    for what TOML cannot hold, as `scene_to_dict`); its arrays written a line at a time, not
    an item at a time (a fitted trunk's regions: 3,403 lines -> about 300)."""
    import tomli_w

    return compact_arrays(tomli_w.dumps(scene_to_dict(scene)))


#: one array item as tomli_w writes it: a number, a boolean, a plain string, or an array of those
#: already compacted (`compact_arrays`); anything else is left as it is
_ITEM = r'(?:-?[0-9][0-9_.eE+\-]*|-?inf|nan|true|false|"[^"\\\[\]{}\n]*"|\[[^\[\]{}\n"]*\])'
_ARRAY = re.compile(r"\[\n((?:[ ]+" + _ITEM + r",\n)+)([ ]*)\]")
#: the longest line an array is written on
LINE = 100


def compact_arrays(text: str) -> str:
    """tomli_w's arrays (an item per line) written on one line where it fits, else wrapped at
    `LINE` columns, the innermost first; the same TOML values."""

    def one(match) -> str:
        items = [line.strip()[:-1] for line in match.group(1).split("\n")[:-1]]
        indent = match.group(2)
        inline = "[" + ", ".join(items) + "]"
        start = text.rfind("\n", 0, match.start()) + 1
        if match.start() - start + len(inline) + 1 <= LINE:  # and the comma after it
            return inline
        lines, line = [], indent + "    "
        for item in items:
            if len(line) + len(item) + 1 > LINE and line.strip():
                lines.append(line.rstrip())
                line = indent + "    "
            line += item + ", "
        lines.append(line.rstrip())
        return "[\n" + "\n".join(lines) + "\n" + indent + "]"

    while True:
        new = _ARRAY.sub(one, text)
        if new == text:
            return text
        text = new
