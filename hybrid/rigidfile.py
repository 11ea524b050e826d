"""The `[rigid]` table of a scene file, read into a `Rigid` and written back.

`hybrid.scenefile` calls these with its own readers of selectors, schedules and
kind-checked fields (passed in, so that this module imports nothing of it). The
control keys (`keyframe`, `fix`, `fix_root`, `weld`, `hold`, `lock`, `ctrl`,
`integrator`, ...), `load_joints` (the joints `hybrid.loads` takes moments about) and the
`[rigid.ribs]` table (articulated ribs, `[[rigid.ribs.pairs]]`) are checked here for their
form; the names they give are checked against the model when it is compiled
(`hybrid.rigid.controls`, `hybrid.rigid.ribs`).
"""

from __future__ import annotations

import dataclasses

from . import checks
from .errors import SceneError
from .scene import RibPair, Ribs, Rigid, RigidLink

__all__ = [
    "RIGID_KEYS",
    "RIBS_KEYS",
    "RIB_PAIR_KEYS",
    "NAME_LISTS",
    "rigid_from_table",
    "rigid_to_table",
    "reference_angle",
]

#: the keys of [rigid]: the fields of Rigid
RIGID_KEYS = tuple(f.name for f in dataclasses.fields(Rigid))
#: the keys that hold lists of names (bodies, joint name patterns, or joint names)
NAME_LISTS = ("fix", "weld", "hold", "lock", "load_joints")
_LINK_KEYS = ("body", "name", "region", "slide_stiffness_n_per_m3")
_SLIDE_FIELD = next(f for f in dataclasses.fields(RigidLink) if f.name == "slide_stiffness_n_per_m3")
_KINDED = {f.name: f for f in dataclasses.fields(Rigid) if "kind" in f.metadata}
#: the keys of [rigid.ribs] and of each [[rigid.ribs.pairs]] table
RIBS_KEYS = tuple(f.name for f in dataclasses.fields(Ribs))
RIB_PAIR_KEYS = tuple(f.name for f in dataclasses.fields(RibPair))
#: a rib's hinge spring rests within a right angle of where it is drawn (deg)
MAX_REFERENCE_ANGLE_DEG = 90.0


def _fail(where: str, msg: str):
    raise SceneError(f"{where}: {msg}")


def rigid_from_table(source: str, rig, selector, schedule, field_value) -> Rigid:
    """The `Rigid` of a parsed [rigid] table. source: the file's name for messages;
    selector(path, v), schedule(path, v, ncomp), field_value(path, field, v): the scene
    file's readers. Raises SceneError, one line naming the key."""
    where = f"{source}: rigid"
    if not isinstance(rig, dict):
        _fail(where, f"expected a table, received {checks.show(rig)}")
    unknown = [k for k in rig if k not in RIGID_KEYS]
    if unknown:
        _fail(f"{where}.{unknown[0]}", f"unknown key; valid keys here: {sorted(RIGID_KEYS)}")
    if "mjcf" not in rig:
        _fail(where, f"missing required key 'mjcf'; valid keys here: {sorted(RIGID_KEYS)}")
    links = rig.get("links", [])
    if not isinstance(links, list) or not all(isinstance(x, dict) for x in links):
        _fail(f"{where}.links", f"expected an array of tables ([[rigid.links]]), received {checks.show(links)}")
    lk = []
    for k, tbl in enumerate(links):
        p = f"rigid.links[{k}]"
        unknown = [x for x in tbl if x not in _LINK_KEYS]
        if unknown:
            _fail(f"{source}: {p}.{unknown[0]}", f"unknown key; valid keys here: {list(_LINK_KEYS)}")
        for req in ("region", "body"):
            if req not in tbl:
                _fail(f"{source}: {p}", f"missing required key {req!r}; valid keys here: {list(_LINK_KEYS)}")
        slide = {}
        if "slide_stiffness_n_per_m3" in tbl:
            slide["slide_stiffness_n_per_m3"] = field_value(
                f"{p}.slide_stiffness_n_per_m3", _SLIDE_FIELD, tbl["slide_stiffness_n_per_m3"]
            )
        lk.append(
            RigidLink(
                region=selector(f"{p}.region", tbl["region"]),
                body=checks.text(f"{source}: {p}.body", tbl["body"]),
                name=checks.text(f"{source}: {p}.name", tbl.get("name", tbl["body"])),
                **slide,
            )
        )
    kw = {
        "mjcf": checks.text(f"{where}.mjcf", rig["mjcf"]),
        "links": tuple(lk),
        "prefix": checks.text(f"{where}.prefix", rig.get("prefix", "")),
        "add_link_mass": checks.boolean(f"{where}.add_link_mass", rig.get("add_link_mass", True)),
        "fix_root": checks.boolean(f"{where}.fix_root", rig.get("fix_root", False)),
    }
    for key in NAME_LISTS:
        if key in rig:
            kw[key] = _names(f"{where}.{key}", rig[key])
    for key, f in _KINDED.items():
        if key in rig:
            kw[key] = field_value(f"rigid.{key}", f, rig[key])
    if "ctrl" in rig:
        ctrl = rig["ctrl"]
        if not isinstance(ctrl, dict):
            _fail(
                f"{where}.ctrl",
                f"expected a table {{actuator name or pattern = schedule}}, received {checks.show(ctrl)}",
            )
        kw["ctrl"] = {name: schedule(f"rigid.ctrl.{name}", v, 1) for name, v in ctrl.items()}
    if "ribs" in rig:
        kw["ribs"] = _ribs(source, rig["ribs"], field_value)
    return Rigid(**kw)


def _kinded_table(source: str, path: str, tbl, cls, field_value) -> dict:
    """The keyword arguments of dataclass `cls` from TOML table `tbl` at `path`: unknown
    and missing keys refused, each kinded field checked by its kind."""
    keys = [f.name for f in dataclasses.fields(cls)]
    if not isinstance(tbl, dict):
        _fail(f"{source}: {path}", f"expected a table, received {checks.show(tbl)}")
    unknown = [k for k in tbl if k not in keys]
    if unknown:
        _fail(f"{source}: {path}.{unknown[0]}", f"unknown key; valid keys here: {sorted(keys)}")
    kw = {}
    for f in dataclasses.fields(cls):
        if f.name not in tbl:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                _fail(f"{source}: {path}", f"missing required key {f.name!r}; valid keys here: {sorted(keys)}")
            continue
        if "kind" in f.metadata:
            kw[f.name] = field_value(f"{path}.{f.name}", f, tbl[f.name])
    return kw


def _ribs(source: str, tbl, field_value) -> Ribs:
    """The `Ribs` of a [rigid.ribs] table and its [[rigid.ribs.pairs]]."""
    kw = _kinded_table(source, "rigid.ribs", tbl, Ribs, field_value)
    pairs = tbl.get("pairs", [])
    if not isinstance(pairs, list) or not pairs or not all(isinstance(x, dict) for x in pairs):
        _fail(
            f"{source}: rigid.ribs.pairs",
            f"expected a non-empty array of tables ([[rigid.ribs.pairs]]), received {checks.show(pairs)}",
        )
    out = []
    for k, p in enumerate(pairs):
        path = f"rigid.ribs.pairs[{k}]"
        pk = _kinded_table(source, path, p, RibPair, field_value)
        if "reference_angle_deg" in p:
            pk["reference_angle_deg"] = reference_angle(
                f"{source}: {path}.reference_angle_deg", p["reference_angle_deg"]
            )
        out.append(RibPair(**pk))
    return Ribs(pairs=tuple(out), **kw)


def reference_angle(where: str, v) -> float:
    """A rib hinge's spring reference (deg), checked: a number in [-90, 90]."""
    return checks.number(
        where, v, lo=-MAX_REFERENCE_ANGLE_DEG, lo_open=False, hi=MAX_REFERENCE_ANGLE_DEG, hi_open=False
    )


def _names(where: str, v) -> tuple:
    if not isinstance(v, list):
        _fail(where, f'expected a list of names, e.g. ["pelvis"], received {checks.show(v)}')
    for k, x in enumerate(v):
        if not isinstance(x, str) or not x:
            _fail(f"{where}[{k}]", f"expected a non-empty name, received {checks.show(x)}")
    return tuple(v)


def rigid_to_table(r: Rigid, selector_to, schedule_to) -> dict:
    """The [rigid] table of `r` (inverse of `rigid_from_table`): every key but those
    left unset (TOML has no null), so that `--set rigid.KEY...` finds each table."""
    d = {
        "mjcf": str(r.mjcf),
        "prefix": r.prefix,
        "add_link_mass": r.add_link_mass,
        "links": [
            {
                "region": selector_to(k.region),
                "body": k.body,
                "name": k.name,
                **({"slide_stiffness_n_per_m3": k.slide_stiffness_n_per_m3} if k.slide_stiffness_n_per_m3 else {}),
            }
            for k in r.links
        ],
        "fix_root": r.fix_root,
        **{key: list(getattr(r, key)) for key in NAME_LISTS},
    }
    for key in _KINDED:
        if getattr(r, key) is not None:
            d[key] = getattr(r, key)
    d["ctrl"] = {name: schedule_to(s, f"rigid.ctrl.{name}") for name, s in r.ctrl.items()}
    if r.ribs is not None:
        d["ribs"] = _plain(r.ribs)
    return d


def _plain(obj):
    """A Ribs or RibPair as TOML values (tuples as lists, nested pairs as tables)."""
    if dataclasses.is_dataclass(obj):
        return {f.name: _plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (tuple, list)):
        return [_plain(x) for x in obj]
    return obj
