"""What every force and constraint term shares.

A term is a frozen dataclass whose fields carry their kind (`param`): the kind
says how a value is checked and how the scene file spells it, so the TOML keys
of a term are its field names and its checks are written once. A term class
also declares the arrays the compiled step reads for it (`arrays`: name ->
`Rows(dtype, *tail)`, an array of rows the terms add, or a function of nvert
giving the value when the scene lacks the term) and compiles itself in two
phases into a `Build`:

- `compile(self, b, what)`: per term instance, selects its regions, checks its
  values, adds its rows (`b.add_rows`) and marks fixed points (`b.vert_free`);
- `finish(cls, b)`: once per term class present, after every term and rigid
  link is known (`b.moving`), turns the rows into the final arrays; by
  default each `Rows` array, a force's rows on points that do not move left out.

`force(type)` and `constraint(type)` declare a term class; `order_terms`
(called once by `hybrid.terms` with every class, in order) puts
each class in `FORCE_TYPES` or `CONSTRAINT_TYPES` under its TOML `type`; a
term the step calls a kernel for (`flag=True`) also gets its id, the index of
its flag in `MembraneArrays.term_on` and of its call counter.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from collections.abc import Mapping
from typing import ClassVar

import numpy as np

from .. import checks
from .. import regions as _regions
from .. import schedule as _sched
from ..errors import SceneError
from ..mesh.validate import few

__all__ = [
    "param",
    "Rows",
    "force",
    "constraint",
    "order_terms",
    "Term",
    "Build",
    "FORCE_TYPES",
    "CONSTRAINT_TYPES",
    "TERM_CLASSES",
    "FLAGGED",
    "check_value",
    "VALUE_KINDS",
    "claim_points",
    "POINT_CLAIMS",
    "FORMULATIONS",
]

#: how a scene's membrane parameters are meant (`Scene.formulation`): "continuum", material
#: parameters (moduli in N/m, tensions in N/m, drag per area) that mean the same on every
#: mesh, internal forces from an energy or in action-reaction pairs; "paper", the per-point
#: model of Promayon, Baconnier & Puech (1997), kept exactly
FORMULATIONS = ("continuum", "paper")

FORCE_TYPES: dict = {}
CONSTRAINT_TYPES: dict = {}
#: every term class, in registration order
TERM_CLASSES: list = []
#: the term classes with a flag and a kernel, in id order
FLAGGED: list = []

#: kinds checked by `check_value`; "selector" and "schedule" are checked where
#: they are evaluated (hybrid.regions.select, hybrid.schedule.as_schedule)
VALUE_KINDS = (
    "positive",
    "step",
    "floats",
    "nonneg",
    "angle_deg",
    "vec3",
    "target",
    "choice",
    "text",
    "name",
    "integer",
)


def param(kind: str, default=dataclasses.MISSING, **meta):
    """A term field of `kind` (VALUE_KINDS, "selector", or "schedule" with ncomp=1 or 3);
    formulation="paper" (or "continuum") for a field only that formulation accepts."""
    return dataclasses.field(default=default, metadata={"kind": kind, **meta})


class Rows:
    """An array the step reads of shape (nrow, *tail) and `dtype`, one row per
    `Build.add_rows` entry (for a force, the first column is the vertex)."""

    def __init__(self, dtype, *tail: int):
        self.dtype, self.tail = np.dtype(dtype), tail

    def build(self, rows) -> np.ndarray:
        return np.asarray(rows, self.dtype).reshape(-1, *self.tail)

    def __call__(self, nvert: int) -> np.ndarray:  # the value when the scene lacks the term
        return np.zeros((0, *self.tail), self.dtype)


def check_value(where: str, kind: str, value, meta: Mapping | None = None):
    """`value` checked as a field of `kind`; returns it normalised (floats, tuples)."""
    meta = meta or {}
    if kind == "positive":
        return (
            checks.number(where, value, lo=0) if meta.get("hi") is None else checks.positive(where, value, meta["hi"])
        )
    if kind == "step":  # a time step, or "auto": the model's stable-step estimate, halved and rounded down
        if value == "auto":
            return value
        return checks.positive(where, value, meta["hi"])
    if kind == "floats":
        if not isinstance(value, (list, tuple)):
            checks.fail(where, f"expected a list of numbers, received {checks.show(value)}")
        return tuple(checks.number(f"{where}[{i}]", v) for i, v in enumerate(value))
    if kind == "nonneg":
        return checks.number(where, value, lo=0, lo_open=False, hi=meta.get("hi"), hi_open=False)
    if kind == "angle_deg":
        return checks.number(where, value, lo=0, hi=90)
    if kind == "vec3":
        return checks.vec3(where, value)
    if kind == "target":
        if isinstance(value, (list, tuple)) and value and isinstance(value[0], (list, tuple)):
            return checks.vec3_list(where, value)
        return checks.vec3(where, value)
    if kind == "choice":
        return checks.text(where, value, meta["choices"])
    if kind == "text":
        return checks.text(where, value)
    if kind == "name":
        return checks.plain_name(where, value)
    if kind == "integer":
        return checks.integer(where, value, lo=meta["lo"], hi=meta.get("hi"))
    raise ValueError(f"kind {kind!r}: not a value kind {VALUE_KINDS}")


def _term(section: str, toml_type: str, flag: bool):
    def wrap(cls):
        cls.toml_type, cls.section, cls.flag = toml_type, section, flag
        # every term has a name, by default its type: what --without and --set refer to
        cls.__annotations__["name"] = "str"
        cls.name = param("text", toml_type)
        return dataclasses.dataclass(frozen=True)(cls)

    return wrap


def force(toml_type: str, *, flag: bool = True):
    """Class decorator: a force term of TOML type `toml_type`, made a frozen
    dataclass with a last field `name` (default: the type)."""
    return _term("forces", toml_type, flag)


def constraint(toml_type: str, *, flag: bool = True):
    """Class decorator: a constraint term, as `force`; flag=False for a term the
    step has no kernel for (nailed points)."""
    return _term("constraints", toml_type, flag)


def order_terms(classes) -> None:
    """Fill the registry with `classes` in order: the TOML type tables, and the
    ids of the flagged ones (the index of each flag and call counter)."""
    for cls in classes:
        table = FORCE_TYPES if cls.section == "forces" else CONSTRAINT_TYPES
        if cls.toml_type in table:
            raise ValueError(f"term type {cls.toml_type!r} registered twice")
        table[cls.toml_type] = cls
        TERM_CLASSES.append(cls)
        if cls.flag:
            cls.id = len(FLAGGED)
            FLAGGED.append(cls)


def registered_forces() -> tuple:
    """((id, step_force), ...) of the registered force terms that carry their own
    `step_force` kernel, in id order: the step calls those its model has, each compiled apart
    for the model's types and called at its address (`hybrid.step_work.StepWork.force_calls`), so
    that a term no scene of the run has is never compiled."""
    return tuple((cls.id, cls.step_force) for cls in FLAGGED if cls.step_force is not None)


class Term:
    """Mixin of the term dataclasses (see the module docstring)."""

    toml_type: ClassVar[str]
    section: ClassVar[str]  # "forces" or "constraints"
    id: ClassVar[int] = -1
    arrays: ClassVar[dict] = {}
    #: finish after the other classes (damping reads every point's stiffness)
    finish_last: ClassVar[bool] = False
    #: the formulations whose scenes may hold this term (FORMULATIONS)
    formulations: ClassVar[tuple] = FORMULATIONS
    #: the array whose rows are triangles (n, 3): each row kept when any of its corners moves
    triangle_rows: ClassVar[str | None] = None
    #: the kernel `step_force(m, s, w, c)` the step calls for a force term it has no call of
    #: its own for (`registered_forces`): m the model's arrays (this term's among them),
    #: s the state (its vert_pos, vert_vel in), w the step's work (its vert_force added to),
    #: c the inputs
    step_force: ClassVar[object] = None

    def check_formulation(self, formulation: str, what: str) -> None:
        """Refuse, in one SceneError line, a term or a field of a formulation other
        than the scene's (a per-point parameter in a continuum scene, say)."""
        if formulation not in self.formulations:
            ok = sorted(
                c.toml_type for c in TERM_CLASSES if c.section == self.section and formulation in c.formulations
            )
            raise SceneError(
                f"{what}: type {self.toml_type!r} belongs to formulation {self.formulations[0]!r}, "
                f"the scene's formulation is {formulation!r}; expected one of {ok}, or "
                f"formulation = {self.formulations[0]!r}"
            )
        for name, f in self.fields().items():
            only = f.metadata.get("formulation")
            if only is not None and only != formulation and getattr(self, name) is not None:
                ok = [n for n, g in self.fields().items() if g.metadata.get("formulation") == formulation]
                raise SceneError(
                    f"{what}.{name}: a parameter of formulation {only!r}, the scene's formulation "
                    f"is {formulation!r}; expected {' or '.join(ok) or 'no such key'}, or "
                    f"formulation = {only!r}"
                )

    @classmethod
    def fields(cls) -> dict:
        """{field name: dataclasses.Field} of the user's fields, name included."""
        return {f.name: f for f in dataclasses.fields(cls)}

    @classmethod
    def required(cls) -> tuple:
        return tuple(
            f.name
            for f in dataclasses.fields(cls)
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        )

    def value(self, field: str, what: str):
        """Field `field` checked by its kind (None stays None when it is the default)."""
        f = self.fields()[field]
        v = getattr(self, field)
        if v is None and f.default is None:
            return None
        return check_value(f"{what}.{field}", f.metadata["kind"], v, f.metadata)

    def compile(self, b: Build, what: str):
        """Mark the term present; returns the vertices of its `region` (None without one)."""
        if self.id >= 0:
            b.term_on[self.id] = 1
        if "region" in self.fields():
            return b.region(self.region, f"{what}.region")
        return None

    @classmethod
    def finish(cls, b: Build) -> None:
        """Turn the rows of every term of this class into its `Rows` arrays; a
        force's rows on points that do not move are left out."""
        names = [n for n, spec in cls.arrays.items() if isinstance(spec, Rows)]
        columns = [b.rows[n] for n in names]
        if cls.triangle_rows is not None:  # rows are triangles: kept when any corner moves
            tri = np.asarray(b.rows[cls.triangle_rows], np.int64).reshape(-1, 3)
            keep = b.moving[tri].any(axis=1)
            columns = [np.asarray(col)[keep] if keep.size else [] for col in columns]
        elif cls.section == "forces" and names:
            columns = b.keep_moving(*columns)
        for n, col in zip(names, columns):
            b.out[n] = cls.arrays[n].build(col)


#: what a constraint does to its points, as an error message says it
POINT_CLAIMS = {
    "nailed": "nailed",
    "prescribed": "prescribed",
    "keep_in": "kept in a region",
    "linked": "linked to a rigid body",
}
# pairs of point constraints that cannot both hold on one point: each sets the
# position its own way (two nails agree; two keep-in regions may overlap)
_CONFLICTS = {
    frozenset(p)
    for p in (
        ("nailed", "prescribed"),
        ("nailed", "keep_in"),
        ("prescribed", "keep_in"),
        ("prescribed",),
        ("linked", "nailed"),
        ("linked", "prescribed"),
        ("linked", "keep_in"),
    )
}


def claim_points(claims: list, idx, kind: str, what: str) -> None:
    """Record that constraint `what` (of `kind`, a key of POINT_CLAIMS) sets the
    points idx, after refusing it, with one SceneError line naming the points
    (a few and their count) and both constraints, if an earlier claim on any of
    them cannot hold together with it. claims: the list of (kind, what, idx) so far."""
    idx = np.asarray(idx, dtype=np.int64)
    for kind0, what0, idx0 in claims:
        if frozenset((kind, kind0)) not in _CONFLICTS:
            continue
        both = np.intersect1d(idx, idx0)
        if both.size:
            raise SceneError(
                f"{what}: {both.size} points are also {POINT_CLAIMS[kind0]} by {what0}: vertices "
                f"{few(both.tolist())}; expected a point {POINT_CLAIMS[kind]} or "
                f"{POINT_CLAIMS[kind0]}, not both"
            )
    claims.append((kind, what, idx))


class Build:
    """A model being compiled: what term compile functions read and write.

    mesh, regions {name: vertex indices}, vert_mass (nvert,) kg; written by the
    terms: vert_free (nvert,) uint8, vert_stiffness (nvert,) N/m (each point's
    elastic stiffness, for critical damping and the stability estimate),
    term_on, rows {name: list} (rows accumulated over a class's terms),
    out {array name: value} (the final arrays), schedules; set before the
    finish phase: link_vert (points linked to rigid bodies) and moving
    (nvert,) bool, the points that move (free or linked); claims, the points
    each point constraint sets (`claim_points` refuses two that conflict).
    """

    def __init__(self, mesh, regions: dict, vert_mass: np.ndarray, nterm: int):
        self.mesh = mesh
        self.regions = regions
        self.vert_mass = vert_mass
        self.vert_free = np.ones(mesh.nvert, np.uint8)
        self.vert_stiffness = np.zeros(mesh.nvert)
        self.vert_viscosity = np.zeros(mesh.nvert)  # N s/m, of viscous terms outside damp_coef (stable step)
        self.selectors: dict = {}  # the scene's regions as selectors (face_region)
        self.term_on = np.zeros(nterm, np.uint8)
        self.rows: dict = defaultdict(list)
        self.out: dict = {}
        self.schedules: list = []
        self.schedule_keys: list = []  # (scene key, components) per schedule row: the model's controls
        self.link_vert = np.zeros(0, np.int32)
        self.moving: np.ndarray | None = None
        self.claims: list = []  # (kind, what, points) of the point constraints (claim_points)
        # points off the membrane that the rigid bodies carry (the lungs' wall): (pos (n, 3) m,
        # under (n,) the membrane point whose body carries each (-1: none), weight (n,)), or None
        self.carried: tuple | None = None

    def face_region(self, sel, what: str, idx: np.ndarray) -> np.ndarray:
        """The faces of region `sel` (its points `idx`): those whose centroid it holds when
        it is made of geometry (`hybrid.regions.select_faces`), else those with two of
        their points in it."""
        return _regions.faces_on(sel, self.mesh, self.selectors, idx, name=what)

    def region(self, sel, what: str) -> np.ndarray:
        """The sorted vertex indices a selector picks (SceneError naming `what` if none)."""
        return _regions.select_on(sel, self.mesh, name=what, regions=self.regions)

    def schedule(self, value, what: str, ncomp: int) -> int:
        """Row of the validated schedule `value` in the model's schedule table."""
        self.schedules.append(_sched.as_schedule(value, name=what, ncomp=ncomp))
        self.schedule_keys.append((what, ncomp))
        return len(self.schedules) - 1

    def add_rows(self, **columns) -> None:
        """Append rows to the named arrays (each value a sequence of rows)."""
        for name, col in columns.items():
            self.rows[name] += np.asarray(col).tolist()

    def keep_moving(self, verts, *columns):
        """verts and its parallel columns restricted to moving points (forces on
        nailed and prescribed points are never used), as arrays."""
        ok = self.moving[np.asarray(verts, dtype=np.int64)] if len(verts) else np.zeros(0, bool)
        return [np.asarray(x)[ok] if len(x) else np.asarray(x) for x in (verts, *columns)]
