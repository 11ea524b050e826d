"""A TOML scene file (or its mapping) read into a `Scene`: every value checked where it
is read, refused in one line naming the file, the key and the value."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

from .. import checks
from .. import regions as R
from .. import schedule as S
from ..errors import SceneError
from ..rigidfile import rigid_from_table
from ..scene import Masses, MeshSpec, Scene
from ..terms import CONSTRAINT_TYPES, FORCE_TYPES
from ..terms.base import check_value

__all__ = ["scene_from_dict", "load_scene"]


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
