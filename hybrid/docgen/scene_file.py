"""docs/scene-file.md, written from the dataclasses: every term's keys, kinds, defaults
and bounds from its fields through the registry, the top level's and `[mesh]`'s from
`Scene` and `MeshSpec`; the tables whose fields carry no kind (masses, selectors,
schedules, the rigid part) described below field by field."""

from __future__ import annotations

import dataclasses
import inspect
import re
import typing

from .. import regions as R
from .. import scenefile
from .. import schedule as S
from ..integrators import INTEGRATORS
from ..scene import Masses, MeshSpec, RibPair, Ribs, Rigid, RigidLink, Scene
from ..terms.base import CONSTRAINT_TYPES, FORCE_TYPES, FORMULATIONS

__all__ = ["render", "selector_classes"]

# a field's unit from its name's suffix (the project's naming rule), longest first
_SUFFIX_UNITS = (
    ("_n_s_per_m3", "N s/m^3"),
    ("_n_s_per_m", "N s/m"),
    ("_n_per_m", "N/m"),
    ("_kg_per_m2", "kg/m^2"),
    ("_m_s2", "m/s^2"),
    ("_m_s", "m/s"),
    ("_deg", "deg"),
    ("_pa", "Pa"),
    ("_kg", "kg"),
    ("_m", "m"),
    ("_s", "s"),
    ("_n", "N"),
)

# the tables without kinds: {field: (unit, default as the file spells it, valid values)}
_MASSES = {
    "total_kg": ("kg", "none", "a number > 0, spread in proportion to each point's share of the area"),
    "density_kg_per_m2": (
        "kg/m^2",
        "none",
        "{region = number > 0, ...}; the last listed region wins where regions overlap; every point covered",
    ),
    "per_vertex_kg": ("kg", "none", "[m0, m1, ...], one number > 0 per point"),
}
_RIGID = {
    "mjcf": (
        "-",
        "*required*",
        '"trunk" (the packaged two-rib model), a path to an MJCF file, or "package:model" (e.g. "myo_sim:myotorso")',
    ),
    "links": ("-", "[]", "[[rigid.links]] tables, below"),
    "prefix": ("-", '""', "a string prepended to the model's names"),
    "add_link_mass": ("-", "true", "true or false: add the linked points' masses to their bodies"),
    "keyframe": (
        "-",
        "none",
        "the name of a keyframe of the model: the run starts from it (qpos, qvel, "
        "act, ctrl), the membrane placed against the bodies there",
    ),
    "fix": (
        "-",
        "[]",
        "[body, ...]: their joints removed, each body fixed to its parent where it starts "
        "(a body on the world stays there)",
    ),
    "fix_root": (
        "-",
        "false",
        "true or false: every free-floating root body (a free joint on the world) fixed where it starts",
    ),
    "weld": ("-", "[]", "[body, ...]: welded to the world where they start (a MuJoCo weld, time constant 2 dt)"),
    "hold": (
        "-",
        "[]",
        '[joint or pattern, ...] ("*": all but free joints): held where they start by '
        "springs, replacing the joint's own stiffness and damping",
    ),
    "hold_stiffness_nm_per_rad": ("N m/rad", "1000", "a number > 0 (N/m for a slide joint)"),
    "hold_damping_nms_per_rad": ("N m s/rad", "10", "a number >= 0 (N s/m for a slide joint)"),
    "lock": (
        "-",
        "[]",
        "[hinge or slide joint or pattern, ...]: locked where they start (MuJoCo joint equalities, time constant 2 dt)",
    ),
    "load_joints": (
        "-",
        "[]",
        "[joint, ...]: the membrane's loads and the intra-abdominal pressure's moment "
        'are also given about each joint\'s anchor (hybrid.loads; docs/outputs.md, "Loads on the skeleton")',
    ),
    "ctrl": (
        "-",
        "{}",
        "{actuator or pattern = schedule}: the actuators' ctrl set before every step "
        "(a number, a breathing waveform or a table)",
    ),
    "integrator": ("-", "the MJCF's", 'MuJoCo\'s integrator: "Euler", "RK4", "implicit" or "implicitfast"'),
    "ribs": ("-", "none", "a [rigid.ribs] table, below: articulated ribs added to the model"),
}
_RIBS = {
    "body": ("-", "*required*", "the thoracic body of the model the ribs hang on"),
    "pairs": ("-", "*required*", "[[rigid.ribs.pairs]] tables, below; at least one"),
}
_PAIRS = {
    "name": (
        "-",
        "*required*",
        "a name: the bodies NAME_left, NAME_right and their joints, sites and tendon (new names in the model)",
    ),
    "head_m": (
        "m",
        "*required*",
        "[x, y, z]: the left rib's costovertebral joint where the model starts, "
        "at least radius_m left of the mid-sagittal plane",
    ),
    "front_m": (
        "m",
        "*required*",
        "[x, y, z]: the left rib's anterior end, at least radius_m left of the plane and 4 radius_m from the head",
    ),
    "half_width_m": (
        "m",
        "*required*",
        "a number > 0, more than the head's and the anterior end's distance from the mid-sagittal plane",
    ),
    "stiffness_n_m_per_rad": ("N m/rad", "12.0", "a number > 0 and <= 1e12: the hinge spring"),
    "damping_n_m_s_per_rad": ("N m s/rad", "0.05", "a number >= 0 and <= 1e12"),
    "reference_angle_deg": (
        "deg",
        "0.0",
        "a number in [-90, 90]: the spring's rest angle beyond the pose "
        "that holds the rib's weight where drawn (positive lifts)",
    ),
}
_LINKS = {
    "region": ("-", "*required*", "a selector (see Regions)"),
    "body": ("-", "*required*", "the name of a body of the MJCF model"),
    "name": ("-", "the body's name", "a string (what --without and --set refer to)"),
    "slide_stiffness_n_per_m3": ("N/m^3", "0", "a number >= 0: 0, the points follow the body; above, they slide on it"),
}
# the selectors' fields' units and values (a field not here: its unit from its name)
_SELECTOR_FIELDS = {
    "indices": (
        "-",
        "[i, j, ...], vertex indices >= 0 (of a mesh file: its points, which keep their indices at every `mesh.level`; the new points between two of them join the region)",
    ),
    "point": ("m", "[x, y, z]"),
    "normal": ("-", "[x, y, z], non-zero"),
    "center": ("m", "[x, y, z]"),
    "radius": ("m", "a number > 0"),
    "radius_m": ("m", "a number > 0"),
    "lo": ("m", "[x, y, z], lo <= hi"),
    "hi": ("m", "[x, y, z]"),
    "points": ("m", "[[x, y, z], ...]"),
    "parts": ("-", "[selector, ...], not empty"),
    "base": ("-", "a selector"),
    "minus": ("-", "a selector"),
    "from_deg": ("deg", "a number in [-360, 360]"),
    "to_deg": ("deg", "a number in [-360, 360]"),
}
_SCHEDULES = {"breathing": S.Breathing, "table": S.Table}
_SCHEDULE_FIELDS = {
    "period_s": ("s", "a number > 0"),
    "inspiration_fraction": ("-", "a number in (0, 1)"),
    "peak": ("the field's", "a number; *required* in a file"),
    "onset_s": ("s", "a number >= 0"),
    "t_s": ("s", "[t0, t1, ...], strictly increasing"),
    "value": ("the field's", "one per time: numbers, or [x, y, z] for a vector field"),
    "periodic": ("-", "true or false: repeat with the table's span"),
}


def _unit(name: str, meta: dict) -> str:
    if "unit" in meta:
        return meta["unit"]
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return "-"


def _show(v) -> str:
    """A default as the scene file spells it."""
    if v is dataclasses.MISSING:
        return "*required*"
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    if isinstance(v, float):
        text = f"{v:g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e-")
        return text if "e" in text or "." in text else f"{text}.0"
    return str(v)


def _valid(kind: str, meta: dict) -> str:
    """What a field of `kind` accepts, as `hybrid.terms.base.check_value` checks it."""
    if kind == "positive":
        return "a number > 0" + (f" and <= {_show(float(meta['hi']))}" if meta.get("hi") is not None else "")
    if kind == "step":
        return f'a number > 0 and <= {_show(float(meta["hi"]))}, or "auto" (half the stable-step estimate, rounded down to 1, 2 or 5 x 10^k; with implicit Euler 4 times the symplectic Euler estimate, at most 0.01 s)'
    if kind == "floats":
        return "[value, ...], finite numbers"
    if kind == "nonneg":
        return "a number >= 0" + (f" and <= {_show(float(meta['hi']))}" if meta.get("hi") is not None else "")
    if kind == "angle_deg":
        return "a number in (0, 90)"
    if kind == "integer":
        return (
            f"an integer in {meta['lo']}..{meta['hi']}" if meta.get("hi") is not None else f"an integer >= {meta['lo']}"
        )
    if kind == "choice":
        return "one of " + ", ".join(f'"{c}"' for c in meta["choices"])
    if kind == "vec3":
        return "[x, y, z], finite"
    if kind == "target":
        return "[x, y, z], or [[x, y, z], ...] one per point"
    if kind == "text":
        return "a string"
    if kind == "name":
        return "a plain name (no path separator, no '..')"
    if kind == "selector":
        return "a selector (see Regions)"
    if kind == "schedule":
        return (
            "a schedule: a number, breathing or table (see Schedules)"
            if meta.get("ncomp") == 1
            else "a schedule: [x, y, z] or a table (see Schedules)"
        )
    # a kind added since: its bounds, as far as the field declares them
    bounds = [f">= {_show(meta['lo'])}"] if meta.get("lo") is not None else []
    bounds += [f"<= {_show(meta['hi'])}"] if meta.get("hi") is not None else []
    return f"a {kind.replace('_', ' ')} value" + (" " + " and ".join(bounds) if bounds else "")


def _row(*cells) -> str:
    return "| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |"


_HEAD = ["| key | unit | default | valid values |", "| --- | --- | --- | --- |"]


def _only(meta: dict) -> str:
    """The note of a field only one formulation accepts."""
    return f'; only with formulation = "{meta["formulation"]}"' if meta.get("formulation") else ""


def _field_rows(fields) -> list[str]:
    return _HEAD + [
        _row(
            f"`{f.name}`",
            _unit(f.name, f.metadata),
            _show(f.default),
            _valid(f.metadata["kind"], f.metadata) + _only(f.metadata),
        )
        for f in fields
    ]


def _doc(cls) -> str:
    """A class's docstring as one paragraph per blank-line-separated block."""
    text = inspect.cleandoc(cls.__doc__ or "")
    if text.startswith(f"{cls.__name__}("):  # the signature dataclasses write for a class without one
        return ""
    return "\n\n".join(" ".join(block.split()) for block in text.split("\n\n") if block.strip())


def _default(f) -> str:
    if f.default_factory is not dataclasses.MISSING:
        return _show(f.default_factory())
    return _show(f.default)


def _hand_rows(cls, table: dict) -> list[str]:
    """The rows of `cls`'s fields, in its order: as `table` describes them, or (a field
    added since) from its name, default and kind alone."""
    rows = []
    for f in dataclasses.fields(cls):
        if f.name in table:
            unit, default, valid = table[f.name]
        else:
            unit, default = _unit(f.name, f.metadata), _default(f)
            valid = _valid(f.metadata["kind"], f.metadata) if "kind" in f.metadata else f"see {cls.__name__}"
        rows.append(_row(f"`{f.name}`", unit, default, valid))
    return _HEAD + rows


def _terms(types: dict, section: str) -> list[str]:
    out = []
    for toml_type, cls in types.items():
        out += [f'### `type = "{toml_type}"` ({cls.__name__})', "", _doc(cls), ""]
        formulations = tuple(getattr(cls, "formulations", FORMULATIONS))
        if set(formulations) != set(FORMULATIONS):
            out += ["Only in a scene with " + " or ".join(f'formulation = "{x}"' for x in formulations) + ".", ""]
        out += _field_rows(dataclasses.fields(cls)) + [""]
    return out


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower().rstrip("_")


def selector_classes() -> dict:
    """{the scene file's selector key: its `hybrid.regions` class}, "all" first: the
    file's keys (`hybrid.scenefile`) matched to the classes by name (HalfSpace is
    half_space, Union_ union)."""
    classes = {_snake(c.__name__): c for c in typing.get_args(R.Selector) if c is not str}
    keys = ["all", *scenefile._SELECTOR_KINDS]
    unmatched = [k for k in keys if k not in classes]
    if unmatched:
        raise RuntimeError(
            f"docgen: selector keys {unmatched} of hybrid.scenefile have no class of that name "
            f"in hybrid.regions.Selector"
        )
    return {k: classes[k] for k in keys}


def _selectors() -> list[str]:
    out = ["| selector | fields | what it picks |", "| --- | --- | --- |"]
    for key, cls in selector_classes().items():
        fields = dataclasses.fields(cls)
        if key == "all":
            spelling = '`"all"` or `"REGION"`'
        elif key == "border":
            spelling = "`{ border = true }`"
        elif len(fields) == 1:  # a list: indices, points, parts
            spelling = f"`{{ {key} = [...] }}`"
        else:
            spelling = f"`{{ {key} = {{ " + ", ".join(f"{f.name} = ..." for f in fields) + " } }`"
        described = (
            "; ".join(
                f"`{f.name}` ({unit}): {valid}"
                for f in fields
                for unit, valid in [_SELECTOR_FIELDS.get(f.name, (_unit(f.name, {}), "-"))]
            )
            or "-"
        )
        what = _doc(cls) or {"union": "Vertices in any of the parts.", "intersection": "Vertices in every part."}.get(
            key, ""
        )
        if key == "all":
            what += " A region's name: the vertices of that region, defined above."
        out.append(_row(spelling, described, what))
    return out


def _schedules() -> list[str]:
    out = []
    for key, cls in _SCHEDULES.items():
        fields = dataclasses.fields(cls)
        out += [f"`{{ {key} = {{ ... }} }}` ({cls.__name__}): {_doc(cls)}", ""]
        out += _HEAD
        for f in fields:
            unit, valid = _SCHEDULE_FIELDS.get(f.name, (_unit(f.name, {}), "-"))
            default = "*required*" if f.name == "peak" else _show(f.default)
            out.append(_row(f"`{f.name}`", unit, default, valid))
        out.append("")
    return out


def render() -> str:
    """The text of docs/scene-file.md."""
    top = [f for f in dataclasses.fields(Scene) if "kind" in f.metadata]
    tables = [k for k in scenefile._TOP if k not in {f.name for f in top}]
    lines = [
        "# The scene file",
        "",
        "<!-- Generated by `python -m hybrid.docgen` from the dataclasses (hybrid/scene.py,",
        "hybrid/terms/, hybrid/regions.py, hybrid/schedule.py); do not edit by hand. -->",
        "",
        "A scene is a TOML file (or the same dataclasses in Python: `hybrid.Scene` and the",
        "classes named below). SI units throughout; a key's unit is in its name (`_m`, `_s`,",
        "`_kg`, `_n_per_m`, ...). A key not marked *required* may be left out; *none* means",
        "absent. Unknown keys, wrong types and values outside the ranges below are refused",
        "with one line naming the file, the key and the value. Relative paths (a mesh file, an",
        "MJCF file) resolve in the scene file's folder. `models/scenes/breathing.toml` is a",
        "complete, commented example.",
        "",
        "```toml",
        'name = "my_scene"',
        "dt_s = 1e-3",
        "[mesh]",
        'generator = "icosphere"',
        "subdivisions = 2",
        "[masses]",
        "total_kg = 4.0",
        "[regions]",
        "top = { half_space = { point = [0, 0, 0.07], normal = [0, 0, 1] } }",
        "[[forces]]",
        'type = "gravity"',
        "[[forces]]",
        'type = "membrane"',
        "youngs_modulus_n_per_m = 1000.0",
        "[[forces]]",
        'type = "damping"',
        "drag_n_s_per_m3 = 500.0",
        "[[constraints]]",
        'type = "nailed"',
        'region = "top"',
        "[[constraints]]",
        'type = "volume"',
        "```",
        "",
        "## Top level",
        "",
        *_field_rows(top),
        "",
        "Tables: " + ", ".join(f"`{t}`" for t in tables) + " (`mesh` and `masses` *required*).",
        "",
        "`dt_s` left out: the MJCF's own timestep (`<option timestep>`) for a scene with a rigid part,",
        "else 1e-3 s. MuJoCo keeps the MJCF's own integrator unless `rigid.integrator` sets it; the",
        "summary's `rigid` table records the step and integrator used and where each came from.",
        "",
        "`integrator`, the membrane's (`hybrid.integrators`, the one list):",
        "",
        *[
            f"- `{i.name}`: {i.about}"
            + (' (formulation "continuum" only: it needs the forces\' Hessian)' if i.needs_hessian else "")
            + "."
            for i in INTEGRATORS
        ],
        "",
        '`formulation` says how the membrane\'s parameters are meant. "paper" is the per-point model of Promayon,',
        "Baconnier & Puech (1997) kept exactly (its stiffnesses act on points, so their meaning",
        'changes with the mesh); "continuum" takes material parameters that mean the same on',
        "every mesh. A term or key marked below for one formulation is refused, in one line, in",
        "a scene of the other.",
        "",
        "## `[mesh]` (MeshSpec)",
        "",
        _doc(MeshSpec),
        "",
        "Either `path` or `generator`, not both.",
        "",
        *_field_rows(dataclasses.fields(MeshSpec)),
        "",
        "## `[masses]` (Masses)",
        "",
        "The table is *required*, with exactly one of these keys.",
        "",
        *_hand_rows(Masses, _MASSES),
        "",
        "## `[regions]`: selectors",
        "",
        "`name = selector`, evaluated in order on the rest positions when the scene is compiled;",
        'a selector may name a region defined before it (or `"all"`). A region that selects no',
        f"point is refused. Selectors nest (union, intersection, difference) up to {R.MAX_SELECTOR_DEPTH} levels.",
        "",
        *_selectors(),
        "",
        "## `[[forces]]`",
        "",
        "Each table has `type` (below) and the type's keys. `name` (default: the type) is what",
        "`--without NAME` and `--set forces.NAME.KEY=VALUE` refer to; names are unique in a scene.",
        "",
        *_terms(FORCE_TYPES, "forces"),
        "## `[[constraints]]`",
        "",
        "As forces: `type`, its keys, and `name`.",
        "",
        *_terms(CONSTRAINT_TYPES, "constraints"),
        "## Schedules",
        "",
        "A field that varies in time (a muscle's stiffness, an applied force, a prescribed",
        "displacement, an attraction's offset) takes a schedule: a number (a scalar field) or",
        "`[x, y, z]` (a vector field) for a constant, or one of these tables. In Python, any",
        "callable `f(t_s)` is also a schedule (`hybrid.Function`; it cannot be written to a file).",
        "",
        *_schedules(),
        "## `[rigid]` (Rigid)",
        "",
        _doc(Rigid),
        "",
        *_hand_rows(Rigid, _RIGID),
        "",
        "### `[[rigid.links]]` (RigidLink)",
        "",
        _doc(RigidLink),
        "",
        *_hand_rows(RigidLink, _LINKS),
        "",
        "### `[rigid.ribs]` (Ribs)",
        "",
        _doc(Ribs),
        "",
        *_hand_rows(Ribs, _RIBS),
        "",
        "### `[[rigid.ribs.pairs]]` (RibPair)",
        "",
        _doc(RibPair),
        "",
        *_hand_rows(RibPair, _PAIRS),
        "",
        "## Overrides: `--set KEY=VALUE`",
        "",
        "`hybrid run SCENE --set KEY=VALUE` (and `hybrid.load(SCENE, overrides=[...])`) changes",
        "one key: KEY is a dotted path in this structure, an element of `forces`, `constraints`",
        "or `rigid.links` (or `rigid.ribs.pairs`) chosen by its `name` or its index; VALUE is a TOML value (a bare word",
        "is a string). Examples: `dt_s=5e-4`, `forces.muscle.stiffness.breathing.peak=80`,",
        "`forces.2.region=all`, `mesh.radius_m=0.1`. `--without NAME` removes a term or a",
        "rigid link by name.",
        "",
    ]
    return "\n".join(lines)
