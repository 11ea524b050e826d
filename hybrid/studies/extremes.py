"""A catalogue of stiff and extreme cases, each ending stable, diverged or refused.

`run(out_dir)` writes `extremes.json` and `extremes.md`:

    {"cases": [{"name", "outcome": "stable" | "diverged" | "refused", "message",
                "volume_rel_error_max": x or null, "step": n or null, "dt_s", "reasonable",
                "what", "wall_s"}, ...],
     "reasonable_failures": [names], "bugs": [...]}

- refused: the scene does not load (SceneError, MeshError, RigidError,
  ConstraintError at compile time): the message.
- diverged: the run raised SimulationDiverged (or ConstraintError: the volume
  projection has no root) at `step`: the message, with the step it suggests.
- stable: the run finished; `volume_rel_error_max` is the largest |V - V0| / V0
  sampled every few steps (0 for a scene without the volume constraint).

Anything else raised is a bug of hybrid: it is caught, listed in "bugs" (type,
message) and the case reported as diverged with the message prefixed "BUG". A
non-finite state that was not detected is a bug too. `reasonable` marks the cases
a user would plausibly run; `reasonable_failures` lists those that do not end
stable. Membrane cases start from `hybrid.demo.membrane_demo` (80 points, one
breath); rib cases from the coupled breathing scene, the MJCF modified in a
temporary folder; `continuum_*` cases from `continuum_demo` (the same sphere in the
continuum formulation). Every stiff case (`STIFF`) is run again with implicit
Euler at its own step, as the row `<case>/implicit_euler`: refused in the paper
formulation (implicit Euler needs the continuum one's Hessians).
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
import time
import traceback
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..demo import membrane_demo
from ..errors import ConstraintError, HybridError, SimulationDiverged
from ..mesh import Mesh, uv_sphere
from ..model import Model, compile_scene
from ..outputs import write_text as _write_text
from ..regions import HalfSpace
from ..resolve import resolve_scene
from ..rigid import resolve_mjcf
from ..scene import AppliedForce, Damping, Gravity, Membrane, MeshSpec, Muscle, MuscleFibres, Scene, ShapeMemory
from ..schedule import Breathing
from ..simulation import Simulation
from .stability.report import finite, write_json

__all__ = ["run", "cases", "run_case", "Case", "continuum_demo", "implicit_variant", "STIFF"]

OUTCOMES = ("stable", "diverged", "refused")


@dataclass
class Case:
    name: str
    what: str
    build: Callable[[], object]  # -> Scene or Model; may raise HybridError (refused)
    duration_s: float = 4.0  # one breath
    perturb_l0: float = 0.0  # initial random displacement of the free points, in mean edges
    reasonable: bool = True  # would a user plausibly run it?
    small_duration_s: float = 0.3


def _replace_force(scene: Scene, kind, **changes) -> Scene:
    return dataclasses.replace(
        scene, forces=tuple(dataclasses.replace(f, **changes) if isinstance(f, kind) else f for f in scene.forces)
    )


def _scaled(scene: Scene, kind, field: str, factor: float) -> Scene:
    return dataclasses.replace(
        scene,
        forces=tuple(
            dataclasses.replace(f, **{field: getattr(f, field) * factor}) if isinstance(f, kind) else f
            for f in scene.forces
        ),
    )


def _schedule_x(scene: Scene, kind, field: str, factor: float) -> Scene:
    """The scene with the schedule `field` of its `kind` terms times factor (a
    Breathing waveform's peak, or a number)."""

    def scale(f):
        if not isinstance(f, kind):
            return f
        s = getattr(f, field)
        return dataclasses.replace(
            f, **{field: dataclasses.replace(s, peak=s.peak * factor) if isinstance(s, Breathing) else s * factor}
        )

    return dataclasses.replace(scene, forces=tuple(scale(f) for f in scene.forces))


def _flat_demo(thickness_ratio: float) -> Scene:
    """The demo's sphere squashed along z to an ellipsoid of half-thickness
    thickness_ratio * radius, its regions squashed alike."""
    base = membrane_demo()
    r = base.mesh.radius_m
    m = uv_sphere(r, base.mesh.segments, base.mesh.rings)
    pos = m.vert_pos * np.array([1.0, 1.0, thickness_ratio])
    mesh = Mesh.from_arrays(pos, m.face_vert, name=f"flat_{thickness_ratio:g}")
    regions = {
        "diaphragm": HalfSpace((0.0, 0.0, 0.05 * thickness_ratio), (0.0, 0.0, 1.0)),
        "pelvis": HalfSpace((0.0, 0.0, -0.09 * thickness_ratio), (0.0, 0.0, -1.0)),
    }
    sc = dataclasses.replace(base, mesh=mesh, regions=regions)
    return _replace_force(sc, Muscle, toward_m=(0.0, 0.0, r * thickness_ratio))


def _breathing():
    return resolve_scene("breathing_paper")


def _rib_variant(tmp: Path, name: str, edit: Callable[[ET.Element], None]) -> Callable[[], Scene]:
    def build():
        sc = _breathing()
        src = resolve_mjcf(sc)
        tree = ET.parse(src)
        edit(tree.getroot())
        path = tmp / f"trunk_{name}.xml"
        tree.write(path)
        return dataclasses.replace(sc, rigid=dataclasses.replace(sc.rigid, mjcf=str(path)))

    return build


def _stiff_ribs(root):
    for j in root.iter("joint"):  # the rib class default and any explicit joint
        if j.get("stiffness"):
            j.set("stiffness", str(float(j.get("stiffness")) * 1e3))
    for t in root.iter("spatial"):
        t.set("stiffness", str(float(t.get("stiffness")) * 1e3))


def _stiffer_ribs(root):
    _stiff_ribs(root)
    _stiff_ribs(root)
    for j in root.iter("joint"):
        if j.get("stiffness"):
            j.set("stiffness", str(float(j.get("stiffness")) / 1e2))
    for t in root.iter("spatial"):
        t.set("stiffness", str(float(t.get("stiffness")) / 1e2))


def _light_ribs(root):
    for b in root.iter("body"):
        if b.get("name", "").startswith("rib_"):
            for g in b.iter("geom"):
                g.set("mass", str(float(g.get("mass")) * 1e-3))


def continuum_demo() -> Scene:
    """membrane_demo in the continuum formulation, the packaged breathing scene's
    materials on the paper's 80-point sphere without ribs: a sheet of Young's modulus
    500 N/m (the central tendon's), muscle fibres of peak tension 20 N/m toward the
    apex with the scene's force-length relation (width 0.67), a drag of 200 N s/m^3, gravity, the bottom nailed, incompressible, dt 1 ms
    (the rigid model's step)."""
    base = membrane_demo()
    return Scene(
        name="continuum_demo",
        mesh=base.mesh,
        masses=base.masses,
        regions=base.regions,
        forces=(
            Gravity(),
            Membrane(500.0),
            Damping(drag_n_s_per_m3=200.0),
            MuscleFibres(
                "diaphragm",
                Breathing(period_s=4.0, inspiration_fraction=0.4, peak=20.0),
                toward_m=(0.0, 0.0, base.mesh.radius_m),
                force_length_width=0.67,
            ),
        ),
        constraints=base.constraints,
        dt_s=1e-3,
        integrator="symplectic_euler",
    )


def implicit_variant(case: Case) -> Case:
    """The case run with implicit Euler at its own step: `<case>/implicit_euler`. A
    paper-formulation case is refused (implicit Euler needs the continuum one)."""

    def build():
        built = case.build()
        if isinstance(built, Model):  # a step set on the compiled model: keep it
            return compile_scene(dataclasses.replace(built.scene, integrator="implicit_euler", dt_s=built.dt_s))
        return dataclasses.replace(built, integrator="implicit_euler")

    return dataclasses.replace(
        case, name=f"{case.name}/implicit_euler", build=build, what=f"{case.what}; implicit Euler at the same step"
    )


#: the stiff cases, each also run with implicit Euler at its own step
STIFF = (
    "shape_memory_x100",
    "shape_memory_x1e4",
    "dt_at_bound",
    "dt_2x_bound",
    "tiny_masses",
    "mesh_40962",
    "muscle_x100",
    "continuum_membrane_x100",
    "continuum_muscle_x100",
    "continuum_mesh_40962",
    "continuum_dt_at_bound",
    "continuum_dt_2x_bound",
)


def cases(tmp: Path) -> list[Case]:
    base = _cases(tmp)
    return base + [implicit_variant(c) for c in base if c.name in STIFF]


def _cases(tmp: Path) -> list[Case]:
    demo = membrane_demo
    cdemo = continuum_demo
    return [
        Case("continuum_baseline", "continuum_demo as defined (80 points, sheet 500 N/m, dt 1 ms)", cdemo),
        Case(
            "continuum_membrane_x100",
            "continuum_demo, Young's modulus 500 -> 5e4 N/m, dt 1 ms",
            lambda: _scaled(cdemo(), Membrane, "youngs_modulus_n_per_m", 100.0),
            reasonable=False,
        ),
        Case(
            "continuum_muscle_x100",
            "continuum_demo, muscle fibres' peak tension 20 -> 2000 N/m, dt 1 ms",
            lambda: _schedule_x(cdemo(), MuscleFibres, "tension_n_per_m", 100.0),
            reasonable=False,
        ),
        Case(
            "continuum_mesh_40962",
            "continuum_demo on an icosphere of 40962 points (same materials, dt 1 ms)",
            lambda: dataclasses.replace(cdemo(), mesh=MeshSpec(generator="icosphere", subdivisions=6, radius_m=0.12)),
            duration_s=0.05,
            small_duration_s=0.005,
            reasonable=False,
        ),
        Case(
            "continuum_dt_at_bound",
            "continuum_demo at dt = model.dt_stable_s",
            lambda: (lambda m: m.with_dt(m.dt_stable_s))(compile_scene(cdemo())),
        ),
        Case(
            "continuum_dt_2x_bound",
            "continuum_demo at dt = 2 x model.dt_stable_s",
            lambda: (lambda m: m.with_dt(2.0 * m.dt_stable_s))(compile_scene(cdemo())),
            reasonable=False,
        ),
        Case(
            "baseline_membrane", "membrane_demo as shipped (80 points, shape memory 3000 N/m, dt 1 ms)", lambda: demo()
        ),
        Case("baseline_coupled", "the breathing scene as shipped (membrane + MuJoCo ribs)", _breathing),
        Case(
            "shape_memory_x100",
            "membrane_demo, shape memory 3000 -> 3e5 N/m, dt 1 ms",
            lambda: _scaled(demo(), ShapeMemory, "stiffness_n_per_m", 100.0),
        ),
        Case(
            "shape_memory_x1e4",
            "membrane_demo, shape memory 3000 -> 3e7 N/m, dt 1 ms",
            lambda: _scaled(demo(), ShapeMemory, "stiffness_n_per_m", 1e4),
            reasonable=False,
        ),
        Case(
            "dt_half_bound",
            "membrane_demo at dt = 0.5 x model.dt_stable_s (what a divergence suggests)",
            lambda: (lambda m: m.with_dt(0.5 * m.dt_stable_s))(compile_scene(demo())),
        ),
        Case(
            "dt_at_bound",
            "membrane_demo at dt = model.dt_stable_s (the per-point linear bound)",
            lambda: (lambda m: m.with_dt(m.dt_stable_s))(compile_scene(demo())),
        ),
        Case(
            "dt_2x_bound",
            "membrane_demo at dt = 2 x model.dt_stable_s",
            lambda: (lambda m: m.with_dt(2.0 * m.dt_stable_s))(compile_scene(demo())),
            reasonable=False,
        ),
        Case(
            "tiny_masses",
            "membrane_demo, total mass 4 kg -> 0.4 g (x 1e-4), dt 1 ms",
            lambda: dataclasses.replace(demo(), masses=dataclasses.replace(demo().masses, total_kg=4e-4)),
            reasonable=False,
        ),
        Case(
            "no_damping", "membrane_demo without its damping term (symplectic Euler)", lambda: demo().without("damping")
        ),
        Case(
            "no_damping_explicit_euler",
            "membrane_demo without damping, explicit Euler (no stable step)",
            lambda: dataclasses.replace(demo().without("damping"), integrator="explicit_euler"),
            reasonable=False,
        ),
        Case(
            "perturbation_0.7_l0",
            "membrane_demo released from random displacements of 0.7 mean edge",
            lambda: demo(),
            perturb_l0=0.7,
        ),
        Case(
            "perturbation_1.5_l0",
            "membrane_demo released from random displacements of 1.5 mean edge",
            lambda: demo(),
            perturb_l0=1.5,
            reasonable=False,
        ),
        Case(
            "sliver_triangles",
            "membrane_demo on a UV sphere of 96 segments x 4 rings (aspect ~ 20)",
            lambda: dataclasses.replace(
                demo(), mesh=MeshSpec(generator="uv_sphere", radius_m=0.12, segments=96, rings=4)
            ),
        ),
        Case(
            "nearly_flat_body",
            "membrane_demo squashed to an ellipsoid 1/100 as thick as wide",
            lambda: _flat_demo(0.01),
        ),
        Case(
            "flat_body",
            "membrane_demo squashed flat (zero thickness, zero volume)",
            lambda: _flat_demo(0.0),
            reasonable=False,
        ),
        Case(
            "mesh_40962",
            "membrane_demo on an icosphere of 40962 points (same 4 kg, 3000 N/m, dt 1 ms)",
            lambda: dataclasses.replace(demo(), mesh=MeshSpec(generator="icosphere", subdivisions=6, radius_m=0.12)),
            duration_s=0.05,
            small_duration_s=0.005,
        ),
        Case(
            "muscle_x100",
            "membrane_demo, muscle peak 60 -> 6000 N/m",
            lambda: _schedule_x(demo(), Muscle, "stiffness", 100.0),
            reasonable=False,
        ),
        Case(
            "rib_springs_x1000",
            "breathing scene, rib hinge stiffness 12 -> 1.2e4 N m/rad, sternum 1000 -> 1e6 N/m",
            _rib_variant(tmp, "stiff", _stiff_ribs),
        ),
        Case(
            "rib_springs_x1e4",
            "breathing scene, rib hinge stiffness 12 -> 1.2e5 N m/rad, sternum 1000 -> 1e7 N/m",
            _rib_variant(tmp, "stiffer", _stiffer_ribs),
            reasonable=False,
        ),
        Case(
            "ribs_light",
            "breathing scene, rib masses x 1e-3 (0.2 kg -> 0.2 g per rib); the linked "
            "points' mass is still added to the ribs (add_link_mass = true)",
            _rib_variant(tmp, "light", _light_ribs),
        ),
        Case(
            "ribs_light_no_link_mass",
            "breathing scene, rib masses x 1e-3 and add_link_mass = false: "
            "the ribs alone carry the membrane's explicit force",
            lambda: (lambda sc: dataclasses.replace(sc, rigid=dataclasses.replace(sc.rigid, add_link_mass=False)))(
                _rib_variant(tmp, "light2", _light_ribs)()
            ),
        ),
        Case(
            "huge_external_force",
            "breathing scene, 1e4 N downward on each dome point",
            lambda: dataclasses.replace(
                _breathing(), forces=_breathing().forces + (AppliedForce("dome", (0.0, 0.0, -1e4)),)
            ),
            reasonable=False,
        ),
        Case(
            "invalid_dt",
            "membrane_demo with dt_s = -1e-3",
            lambda: dataclasses.replace(demo(), dt_s=-1e-3),
            reasonable=False,
        ),
        Case(
            "nan_stiffness",
            "membrane_demo with shape memory stiffness NaN",
            lambda: _replace_force(demo(), ShapeMemory, stiffness_n_per_m=float("nan")),
            reasonable=False,
        ),
        Case(
            "lungs_obstructed_implicit",
            "breathing_lungs at level 0 with an obstructed airway (resistance 1.5 -> 20 cmH2O s/L), "
            "implicit Euler at 20 ms",
            lambda: resolve_scene(
                "breathing_lungs",
                overrides=(
                    "mesh.level=0",
                    "forces.lungs.airway_resistance_cmh2o_s_per_l=20",
                    "integrator=implicit_euler",
                    "dt_s=0.02",
                ),
            ),
            # 100 steps of 80 points: cheap. Until 0.17 its solve stopped at 1.94 s, the lungs' load
            # on the ribs a step late (h c g . (M + h B)^-1 g = 1.98); implicit since (docs/lungs.md)
            small_duration_s=2.0,
        ),
        Case(
            "missing_mjcf",
            "breathing scene pointing at an MJCF file that does not exist",
            lambda: dataclasses.replace(
                _breathing(), rigid=dataclasses.replace(_breathing().rigid, mjcf=str(tmp / "no_such_trunk.xml"))
            ),
            reasonable=False,
        ),
    ]


def _free_perturbation(model: Model, amp_l0: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = rng.normal(size=model.arrays.vert_rest.shape)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u[model.arrays.vert_free == 0] = 0.0
    return amp_l0 * model.mesh.edge_length_mean() * u


def _retry(model: Model, case: Case, duration: float, dt: float, max_steps: int = 20000):
    """Does the same case run `duration` (at most max_steps steps) at the suggested step?"""
    if not (dt > 0 and math.isfinite(dt)):
        return None
    try:
        sim = Simulation(model.with_dt(dt))
        if case.perturb_l0:
            sim.set_state(vert_pos=sim.vert_pos + _free_perturbation(model, case.perturb_l0))
        sim.step(int(min(max_steps, math.ceil(duration / dt))))
        return bool(np.all(np.isfinite(sim.vert_pos)))
    except HybridError:
        return False


def run_case(case: Case, *, small: bool = False, bugs: list | None = None) -> dict:
    """One case: never raises, never returns NaN."""
    bugs = [] if bugs is None else bugs
    out = {
        "name": case.name,
        "what": case.what,
        "reasonable": case.reasonable,
        "outcome": None,
        "message": "",
        "volume_rel_error_max": None,
        "step": None,
        "dt_s": None,
        "dt_suggested_s": None,
        "steps_run": 0,
        "wall_s": 0.0,
    }
    t0 = time.perf_counter()
    try:
        try:
            built = case.build()
            model = built if isinstance(built, Model) else compile_scene(built)
            sim = Simulation(model)
            out["dt_s"] = model.dt_s
            out["dt_stable_s"] = model.dt_stable_s
        except (ConstraintError, HybridError) as e:
            out.update(outcome="refused", message=f"{type(e).__name__}: {e}")
            return out
        if case.perturb_l0:
            sim.set_state(vert_pos=sim.vert_pos + _free_perturbation(model, case.perturb_l0))
        duration = case.small_duration_s if small else case.duration_s
        nstep = max(1, int(math.ceil(duration / model.dt_s)))
        chunk = max(1, min(50, nstep // 20))
        volmax = 0.0
        try:
            while sim.steps_done < nstep:
                sim.step(min(chunk, nstep - sim.steps_done))
                err = sim.volume_rel_error
                if not math.isfinite(err) or not np.all(np.isfinite(sim.vert_pos)):
                    raise FloatingPointError(f"non-finite state after step {sim.steps_done} not detected")
                volmax = max(volmax, err)
        except SimulationDiverged as e:
            out.update(
                outcome="diverged",
                message=str(e),
                step=e.step,
                dt_suggested_s=e.dt_suggested_s,
                steps_run=sim.steps_done,
                volume_rel_error_max=volmax,
            )
            out["stable_at_suggested_dt"] = _retry(model, case, duration, e.dt_suggested_s)
            return out
        except ConstraintError as e:
            out.update(
                outcome="diverged",
                message=f"ConstraintError: {e}",
                step=sim.steps_done,
                steps_run=sim.steps_done,
                volume_rel_error_max=volmax,
            )
            return out
        out.update(
            outcome="stable",
            message=f"{nstep} steps ({nstep * model.dt_s:.3g} s) without failure",
            volume_rel_error_max=volmax,
            steps_run=nstep,
        )
        return out
    except Exception as e:  # a bug of hybrid: report, never crash the study
        bugs.append(
            {"case": case.name, "type": type(e).__name__, "message": str(e), "traceback": traceback.format_exc(limit=6)}
        )
        out.update(outcome="diverged", message=f"BUG {type(e).__name__}: {e}")
        return out
    finally:
        out["wall_s"] = time.perf_counter() - t0


def _markdown(res: dict) -> str:
    L = [
        "# Extreme cases",
        "",
        "| case | outcome | max volume error | step | reasonable | stable at suggested dt | message |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in res["cases"]:
        v = c["volume_rel_error_max"]
        msg = c["message"].replace("|", "/")
        if len(msg) > 160:
            msg = msg[:157] + "..."
        L.append(
            f"| {c['name']} | {c['outcome']} | {'-' if v is None else format(v, '.2e')} | "
            f"{'-' if c['step'] is None else c['step']} | {'yes' if c['reasonable'] else 'no'} | "
            f"{ {True: 'yes', False: 'no', None: '-'}[c.get('stable_at_suggested_dt')] } | {msg} |"
        )
    L += [
        "",
        f"Reasonable cases that do not end stable: {', '.join(res['reasonable_failures']) or 'none'}",
        f"Bugs (unexpected exceptions): {len(res['bugs'])}",
        f"Run time: {res['runtime_s']:.1f} s",
    ]
    return "\n".join(L) + "\n"


def run_named_case(name: str, tmp: str, small: bool) -> tuple[dict, list]:
    """The case called `name` (built in a worker process of `hybrid.sweep`): its row and bugs."""
    case = next(c for c in cases(Path(tmp)) if c.name == name)
    bugs: list = []
    return run_case(case, small=small, bugs=bugs), bugs


def run(out_dir, *, small: bool = False, scheduler: str | None = None, workers: int | None = None) -> dict:
    """Every case, in parallel on the local cores (or a Dask cluster at
    `scheduler`); writes DIR/extremes.json and DIR/extremes.md."""
    from ..sweep import sweep

    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    bugs: list = []
    with tempfile.TemporaryDirectory(prefix="hybrid_extremes_") as tmp:
        params = [dict(name=c.name, tmp=tmp, small=small) for c in cases(Path(tmp))]
        rows = []
        for row, case_bugs in sweep(run_named_case, params, scheduler=scheduler, workers=workers):
            rows.append(row)
            bugs += case_bugs
    res = {
        "small": small,
        "cases": rows,
        "reasonable_failures": [r["name"] for r in rows if r["reasonable"] and r["outcome"] != "stable"],
        "bugs": bugs,
        "runtime_s": time.perf_counter() - t0,
    }
    write_json(out / "extremes.json", res)
    _write_text(out / "extremes.md", _markdown(finite(res)))
    return finite(res)
