"""Scene files: TOML with the same fields as the `hybrid.scene` dataclasses.

`load_scene(path)` reads a file into a `Scene` (relative paths in it resolve in the
file's folder); `scene_from_dict` does the same for an already parsed mapping and
`scene_to_dict` goes back. Validation is strict and every error is a `SceneError`
with one line naming the file and the key path, e.g.
``breathing.toml: forces[2].stiffness_n_per_m: expected a number > 0, received -3``.

The format (SI units; every key optional unless marked *required*)::

    name = "breathing"            # top level: name, formulation, dt_s, integrator, duration_s
    formulation = "paper"         # or "continuum" (the default): what the parameters mean
    dt_s = 1e-3
    integrator = "symplectic_euler"    # or "explicit_euler", "implicit_euler"
    duration_s = 12.0

    [mesh]          # generator = "uv_sphere" | "icosphere" | "icosahedron", or path = "file.stl"
    generator = "uv_sphere"            # radius_m, segments, rings, subdivisions, center_m, unit_scale
    [masses]        # exactly one of: total_kg, density_kg_per_m2 = {region = kg/m^2}, per_vertex_kg = [..]
    total_kg = 4.0

    [regions]       # name = selector, evaluated in order; a later region may name an earlier one
    top = { half_space = { point = [0, 0, 0.07], normal = [0, 0, 1] } }
    #  selectors: "all" | "REGION NAME" | { border = true } | { indices = [0, 5] }
    #    | { half_space = { point, normal } } | { ball = { center, radius } } | { box = { lo, hi } }
    #    | { nearest = [[x, y, z], ...] } | { patch = { center, radius_m } } (a disc of the surface,
    #    its area checked) | { union = [sel, ...] } | { intersection = [sel, ...] }
    #    | { difference = { base = sel, minus = sel } }

    [[forces]]      # type = gravity | damping | shape_memory | mass_spring | muscle
    type = "muscle" #        | applied_force | attraction | soft_volume | pressure | muscle_fibres;
                    #        name defaults to type
    region = "top"
    stiffness = { breathing = { period_s = 4.0, inspiration_fraction = 0.4, peak = 60.0 } }
    toward_m = [0, 0, 0.12]
    #  schedules: a number or [x, y, z] (constant) | { breathing = { period_s, inspiration_fraction,
    #    peak, onset_s } } | { table = { t_s = [..], value = [..], periodic = false } }

    [[constraints]] # type = nailed | keep_in | prescribed | volume
    type = "volume"

    [rigid]         # mjcf (required): "trunk" (the packaged model) or a path; prefix; add_link_mass;
    mjcf = "trunk"  #   keyframe, fix, fix_root, weld, hold, lock, ctrl, integrator, load_joints,
                    #   [rigid.ribs] with [[rigid.ribs.pairs]] (hybrid.rigidfile)
    [[rigid.links]] # region and body required; name defaults to the body's
    region = "ribs"
    body = "rib_left"

Overrides (`apply_overrides`, the command line's ``--set KEY=VALUE``): KEY is a
dotted path in this TOML structure; an element of `forces`, `constraints` or
`rigid.links` is chosen by its `name` (which defaults to its type) or by its
index; VALUE is a TOML value (a bare word is taken as a string). Examples:
``dt_s=5e-4``, ``forces.muscle.stiffness.breathing.peak=80``,
``forces.2.region=all``, ``mesh.radius_m=0.1``, ``rigid.links.rib_left.body=spine``.
"""

from __future__ import annotations

import copy
import dataclasses
import tomllib
from importlib import resources
from pathlib import Path

from . import checks
from . import regions as R
from . import schedule as S
from .errors import SceneError
from .rigidfile import rigid_from_table, rigid_to_table
from .scene import Masses, MeshSpec, Scene
from .terms import CONSTRAINT_TYPES, FORCE_TYPES
from .terms.base import check_value

__all__ = [
    "load_scene",
    "scene_from_dict",
    "scene_to_dict",
    "scene_to_toml",
    "apply_overrides",
    "builtin_scene",
    "packaged_model",
    "builtin_scenes",
]


# ------------------------------------------------------------------ value checks


class _Ctx:
    """Where we are: the file name, for messages."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, path: str, msg: str):
        raise SceneError(f"{self.source}: {path}: {msg}" if path else f"{self.source}: {msg}")


def _where(ctx, path) -> str:
    return f"{ctx.source}: {path}" if path else ctx.source


_is_num = checks.is_number
_show = checks.show


def _num(ctx, path, v, **bounds):
    return checks.number(_where(ctx, path), v, **bounds)


def _int(ctx, path, v, *, lo):
    return checks.integer(_where(ctx, path), v, lo=lo)


def _str(ctx, path, v, choices=None):
    return checks.text(_where(ctx, path), v, choices)


def _bool(ctx, path, v):
    return checks.boolean(_where(ctx, path), v)


def _vec3(ctx, path, v):
    if not isinstance(v, list):  # TOML's arrays only
        ctx.fail(path, f"expected a 3-vector [x, y, z] of finite floats, received {_show(v)}")
    return checks.vec3(_where(ctx, path), v)


def _vec3_list(ctx, path, v):
    return checks.vec3_list(_where(ctx, path), v)


def _table(ctx, path, v, what="a table"):
    if not isinstance(v, dict):
        ctx.fail(path, f"expected {what}, received {_show(v)}")
    return v


def _keys(ctx, path, tbl, valid, required=()):
    unknown = [k for k in tbl if k not in valid]
    if unknown:
        ctx.fail(_join(path, unknown[0]), f"unknown key; valid keys here: {sorted(valid)}")
    for k in required:
        if k not in tbl:
            ctx.fail(path, f"missing required key {k!r}; valid keys here: {sorted(valid)}")


def _join(path, key):
    return f"{path}.{key}" if path else str(key)


# ------------------------------------------------------------------ selectors and schedules

_SELECTOR_KINDS = (
    "border",
    "indices",
    "half_space",
    "ball",
    "box",
    "wedge",
    "nearest",
    "patch",
    "union",
    "intersection",
    "difference",
)


def _selector(ctx, path, v, depth=0):
    """A region selector (module docstring) -> a `hybrid.regions` selector."""
    if depth > R.MAX_SELECTOR_DEPTH:
        ctx.fail(
            path,
            f"selectors nested more than {R.MAX_SELECTOR_DEPTH} levels deep; expected at most "
            f"{R.MAX_SELECTOR_DEPTH} (name an inner part as a region instead)",
        )
    if isinstance(v, str):
        if not v:
            ctx.fail(path, "expected a region name or a selector table, received ''")
        return v
    if not isinstance(v, dict) or len(v) != 1:
        ctx.fail(
            path,
            f"expected a region name or a table with one selector key of {list(_SELECTOR_KINDS)}, received {_show(v)}",
        )
    kind, arg = next(iter(v.items()))
    p = _join(path, kind)
    if kind == "border":
        if arg is not True:
            ctx.fail(p, f"expected true, received {_show(arg)}")
        return R.Border()
    if kind == "indices":
        if not (
            isinstance(arg, list)
            and arg
            and all(isinstance(i, int) and not isinstance(i, bool) and i >= 0 for i in arg)
        ):
            ctx.fail(p, f"expected a non-empty list of vertex indices >= 0, received {_show(arg)}")
        return R.Indices(tuple(int(i) for i in arg))
    if kind == "half_space":
        _table(ctx, p, arg)
        _keys(ctx, p, arg, ("point", "normal"), ("point", "normal"))
        return R.HalfSpace(_vec3(ctx, f"{p}.point", arg["point"]), _vec3(ctx, f"{p}.normal", arg["normal"]))
    if kind == "ball":
        _table(ctx, p, arg)
        _keys(ctx, p, arg, ("center", "radius"), ("center", "radius"))
        return R.Ball(_vec3(ctx, f"{p}.center", arg["center"]), _num(ctx, f"{p}.radius", arg["radius"], lo=0))
    if kind == "box":
        _table(ctx, p, arg)
        _keys(ctx, p, arg, ("lo", "hi"), ("lo", "hi"))
        return R.Box(_vec3(ctx, f"{p}.lo", arg["lo"]), _vec3(ctx, f"{p}.hi", arg["hi"]))
    if kind == "wedge":
        _table(ctx, p, arg)
        _keys(ctx, p, arg, ("from_deg", "to_deg", "center"), ("from_deg", "to_deg"))
        turn = dict(lo=-360.0, hi=360.0, lo_open=False, hi_open=False)
        return R.Wedge(
            _num(ctx, f"{p}.from_deg", arg["from_deg"], **turn),
            _num(ctx, f"{p}.to_deg", arg["to_deg"], **turn),
            _vec3(ctx, f"{p}.center", arg["center"]) if "center" in arg else (0.0, 0.0, 0.0),
        )
    if kind == "nearest":
        return R.Nearest(_vec3_list(ctx, p, arg))
    if kind == "patch":
        _table(ctx, p, arg)
        _keys(ctx, p, arg, ("center", "radius_m"), ("center", "radius_m"))
        return R.Patch(_vec3(ctx, f"{p}.center", arg["center"]), _num(ctx, f"{p}.radius_m", arg["radius_m"], lo=0))
    if kind in ("union", "intersection"):
        if not (isinstance(arg, list) and arg):
            ctx.fail(p, f"expected a non-empty list of selectors, received {_show(arg)}")
        parts = tuple(_selector(ctx, f"{p}[{k}]", x, depth + 1) for k, x in enumerate(arg))
        return R.Union_(parts) if kind == "union" else R.Intersection(parts)
    if kind == "difference":
        _table(ctx, p, arg)
        _keys(ctx, p, arg, ("base", "minus"), ("base", "minus"))
        return R.Difference(
            _selector(ctx, f"{p}.base", arg["base"], depth + 1), _selector(ctx, f"{p}.minus", arg["minus"], depth + 1)
        )
    ctx.fail(p, f"unknown selector; expected one of {list(_SELECTOR_KINDS)} or a region name")


def _schedule(ctx, path, v, ncomp):
    """A schedule: a number / 3-vector, {breathing = {...}} or {table = {...}}."""
    if ncomp == 1 and _is_num(v):
        return S.Constant(_num(ctx, path, v))
    if ncomp == 3 and isinstance(v, list):
        return S.Constant(_vec3(ctx, path, v))
    want = "a number" if ncomp == 1 else "a 3-vector [x, y, z]"
    kinds = ["breathing", "table"] if ncomp == 1 else ["table"]
    if not isinstance(v, dict) or len(v) != 1 or next(iter(v)) not in kinds:
        ctx.fail(path, f"expected {want} or a table with one key of {kinds}, received {_show(v)}")
    kind, arg = next(iter(v.items()))
    p = _join(path, kind)
    _table(ctx, p, arg)
    if kind == "breathing":
        _keys(ctx, p, arg, ("period_s", "inspiration_fraction", "peak", "onset_s"), ("peak",))
        return S.Breathing(
            period_s=_num(ctx, f"{p}.period_s", arg.get("period_s", 4.0), lo=0),
            inspiration_fraction=_num(
                ctx, f"{p}.inspiration_fraction", arg.get("inspiration_fraction", 0.4), lo=0, hi=1
            ),
            peak=_num(ctx, f"{p}.peak", arg["peak"]),
            onset_s=_num(ctx, f"{p}.onset_s", arg.get("onset_s", 0.0), lo=0, lo_open=False),
        )
    _keys(ctx, p, arg, ("t_s", "value", "periodic"), ("t_s", "value"))
    t = arg["t_s"]
    if not (isinstance(t, list) and t):
        ctx.fail(f"{p}.t_s", f"expected a non-empty list of times, received {_show(t)}")
    times = tuple(_num(ctx, f"{p}.t_s[{k}]", x) for k, x in enumerate(t))
    if any(b <= a for a, b in zip(times, times[1:])):
        ctx.fail(f"{p}.t_s", f"expected strictly increasing times, received {_show(t)}")
    val = arg["value"]
    if not (isinstance(val, list) and len(val) == len(times)):
        ctx.fail(f"{p}.value", f"expected {len(times)} values (one per time), received {_show(val)}")
    if ncomp == 1:
        values = tuple(_num(ctx, f"{p}.value[{k}]", x) for k, x in enumerate(val))
    else:
        values = tuple(_vec3(ctx, f"{p}.value[{k}]", x) for k, x in enumerate(val))
    periodic = _bool(ctx, f"{p}.periodic", arg.get("periodic", False))
    if periodic and len(times) < 2:
        ctx.fail(f"{p}.periodic", "a periodic table needs at least 2 samples")
    return S.Table(times, values, periodic)


# ------------------------------------------------------------------ the terms


def _field(ctx, path, f, v):
    """A term field's TOML value as the dataclass holds it, checked by its kind."""
    kind = f.metadata["kind"]
    if kind == "selector":
        return _selector(ctx, path, v)
    if kind == "schedule":
        return _schedule(ctx, path, v, f.metadata["ncomp"])
    if kind in ("vec3", "target") and not isinstance(v, list):
        ctx.fail(path, f"expected a 3-vector [x, y, z] of finite floats, received {_show(v)}")
    return check_value(_where(ctx, path), kind, v, f.metadata)


def _terms(ctx, key, v, types):
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        ctx.fail(key, f"expected an array of tables ([[{key}]]), received {_show(v)}")
    out = []
    for k, tbl in enumerate(v):
        p = f"{key}[{k}]"
        if "type" not in tbl:
            ctx.fail(p, f"missing required key 'type'; expected one of {list(types)}")
        typ = _str(ctx, f"{p}.type", tbl["type"], types)
        cls = types[typ]
        fields = cls.fields()
        _keys(ctx, p, tbl, ("type", *fields), cls.required())
        kw = {name: _field(ctx, f"{p}.{name}", f, tbl[name]) for name, f in fields.items() if name in tbl}
        out.append(cls(**kw))
    return tuple(out)


# ------------------------------------------------------------------ the scene

# the top level's and the mesh table's keys: the fields of Scene and MeshSpec
_TOP_VALUES = {f.name: f for f in dataclasses.fields(Scene) if "kind" in f.metadata}
_TOP = (*_TOP_VALUES, "mesh", "masses", "regions", "forces", "constraints", "rigid")
_MESH = {f.name: f for f in dataclasses.fields(MeshSpec)}


def scene_from_dict(data: dict, *, source: str = "scene", base_dir: str | Path | None = None) -> Scene:
    """Build a `Scene` from a parsed TOML mapping (see the module docstring).

    source: the name used in error messages (the file name); base_dir: the folder
    that relative paths (mesh file, MJCF) resolve in.
    """
    ctx = _Ctx(source)
    _table(ctx, "", data, "a TOML table")
    _keys(ctx, "", data, _TOP, ("mesh", "masses"))
    kw = {k: _field(ctx, k, f, data[k]) for k, f in _TOP_VALUES.items() if k in data}

    mesh = _table(ctx, "mesh", data["mesh"])
    _keys(ctx, "mesh", mesh, _MESH)
    mkw = {k: _field(ctx, f"mesh.{k}", f, mesh[k]) for k, f in _MESH.items() if k in mesh}
    if "path" in mkw:
        if "generator" in mkw:
            ctx.fail("mesh", "expected either path or generator, received both")
        mkw["generator"] = None
    kw["mesh"] = MeshSpec(**mkw)

    masses = _table(ctx, "masses", data["masses"])
    _keys(ctx, "masses", masses, ("total_kg", "density_kg_per_m2", "per_vertex_kg"))
    if len(masses) != 1:
        ctx.fail(
            "masses",
            f"expected exactly one of total_kg, density_kg_per_m2, per_vertex_kg, received {sorted(masses) or 'none'}",
        )
    if "total_kg" in masses:
        kw["masses"] = Masses(total_kg=_num(ctx, "masses.total_kg", masses["total_kg"], lo=0))
    elif "density_kg_per_m2" in masses:
        dens = _table(ctx, "masses.density_kg_per_m2", masses["density_kg_per_m2"], "a table {region = kg/m^2}")
        if not dens:
            ctx.fail("masses.density_kg_per_m2", "expected at least one region")
        kw["masses"] = Masses(
            density_kg_per_m2={k: _num(ctx, f"masses.density_kg_per_m2.{k}", x, lo=0) for k, x in dens.items()}
        )
    else:
        pv = masses["per_vertex_kg"]
        if not isinstance(pv, list) or not pv:
            ctx.fail("masses.per_vertex_kg", f"expected a list of masses, received {_show(pv)}")
        kw["masses"] = Masses(
            per_vertex_kg=tuple(_num(ctx, f"masses.per_vertex_kg[{k}]", x, lo=0) for k, x in enumerate(pv))
        )

    regions = _table(ctx, "regions", data.get("regions", {}))
    kw["regions"] = {name: _selector(ctx, f"regions.{name}", sel) for name, sel in regions.items()}
    kw["forces"] = _terms(ctx, "forces", data.get("forces", []), FORCE_TYPES)
    kw["constraints"] = _terms(ctx, "constraints", data.get("constraints", []), CONSTRAINT_TYPES)

    if "rigid" in data:
        kw["rigid"] = rigid_from_table(
            source,
            data["rigid"],
            lambda p, v: _selector(ctx, p, v),
            lambda p, v, n: _schedule(ctx, p, v, n),
            lambda p, f, v: _field(ctx, p, f, v),
        )

    if base_dir is not None:
        kw["base_dir"] = str(base_dir)
    scene = Scene(**kw)
    names = scene.term_names()
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        ctx.fail(
            "",
            f"term names must be unique (they are what --without and --set refer to); "
            f"{dup} used more than once: give each a distinct name",
        )
    return scene


def load_scene(path: str | Path) -> Scene:
    """Read a TOML scene file into a `Scene` (see the module docstring).

    Raises SceneError, one line naming the file and the key, for a missing file,
    invalid TOML, unknown keys, wrong types or values.
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise SceneError(f"scene file {str(p)!r}: no such file")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{p.name}: not valid TOML: {' '.join(str(exc).split())}") from None
    except UnicodeDecodeError as exc:
        raise SceneError(f"{p.name}: not a UTF-8 text file ({exc.reason})") from None
    except RecursionError:  # the TOML reader recurses once per nested table or list
        raise SceneError(
            f"{p.name}: tables or lists nested too deep to read; expected selectors at most "
            f"{R.MAX_SELECTOR_DEPTH} levels deep"
        ) from None
    return scene_from_dict(data, source=p.name, base_dir=p.resolve().parent)


# ------------------------------------------------------------------ back to a mapping


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
    if ms.path is not None:
        mesh.pop("generator", None)
    mesh["center_m"] = list(ms.center_m)
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
    for what TOML cannot hold, as `scene_to_dict`)."""
    import tomli_w

    return tomli_w.dumps(scene_to_dict(scene))


# ------------------------------------------------------------------ overrides


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


# ------------------------------------------------------------------ built-in scenes


def packaged_model(relative: str) -> Path:
    """The path of a file of the packaged models (MJCF, scene TOMLs): the repository's
    `models/` folder, installed as the package `hybrid.models` (see pyproject.toml).
    A source tree put on sys.path without installing has no `hybrid.models`: there
    the folder is read beside the package."""
    try:
        root = Path(str(resources.files("hybrid.models")))
    except ModuleNotFoundError:
        root = Path(__file__).resolve().parent.parent / "models"
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
