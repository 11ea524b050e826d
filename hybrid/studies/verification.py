"""`hybrid study verification`: the continuum formulation against its oracles, on
three mesh families at three or more resolutions each.

Families: "uv" (UV spheres, the paper's pattern, poles included), "icosphere"
(evenly spaced) and "irregular" (`hybrid.mesh.irregular_sphere`, written to an
STL file and read back, as a remeshed anatomy surface would come in). Oracles:

- `pressure_sphere`: a free sphere (no nails, no volume constraint) inflated by a
  uniform pressure p against the membrane (2D Young's modulus Y, Poisson's ratio
  nu), relaxed with a drag; its volume-equivalent radius against the closed form
  of a Saint Venant-Kirchhoff sheet, Y (s^2 - 1) / (1 - nu) = p R s, dR = (s - 1) R;
- `hanging_sphere`: an inflated sphere (a balloon, in tension everywhere)
  hanging from its nailed upper half under gravity; the descent of its bottom
  against the finest icosphere's (`reference` row), and the three families
  against each other at their finest level (`hanging_finest_spread`); the same
  sphere incompressible instead of inflated is reported beside it (its
  compressed parts wrinkle at the mesh's scale: no oracle);
- `patch_test`: a flat irregular patch under a uniform stretch: the largest force
  on an interior point (exactly 0 in the formulation), against Y l eps;
- `free_body`: a free, undamped, perturbed incompressible sphere, symplectic
  Euler: net internal force and moment, linear momentum over 10^4 steps,
  angular momentum at three steps, energy over 10^5 steps at two;
- `paper_table1`: the paper formulation's Table 1 eigenvalues, to 1e-12.

`run(out_dir, small=False)` writes verification.json
`{"rows": [{"oracle", "mesh_family", "nvert", "measured", "predicted",
"rel_error", ...}], "order": {family: observed spatial order of the pressure
sphere}, "runtime_s"}`, verification.md and verification.png.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from ..mesh import Mesh, icosphere, irregular_sphere, uv_sphere
from ..model import compile_scene
from ..outputs import save_figure as _save_figure
from ..outputs import write_text as _write_text
from ..readouts import internal_forces, net_internal
from ..regions import HalfSpace
from ..scene import Damping, Gravity, Masses, Membrane, Nailed, Pressure, Scene, Volume
from ..simulation import Simulation
from .stability.report import write_json

__all__ = [
    "run",
    "family_meshes",
    "pressure_sphere",
    "hanging_sphere",
    "patch_test",
    "free_body",
    "closed_form_inflation",
]

RADIUS_M = 0.12
YOUNGS_N_PER_M = 1000.0
POISSON = 0.3
PRESSURE_PA = 200.0  # a 1% strain: dR about 1 mm
HANGING_YOUNGS_N_PER_M = 2000.0
HANGING_PRESSURE_PA = 1000.0  # tension pR/2 = 60 N/m, above what the weight changes: no compression
MASS_KG = 4.0
FAMILIES = ("uv", "icosphere", "irregular")


def family_meshes(family: str, small: bool, folder: Path) -> list[Mesh]:
    """The meshes of a family, coarse to fine (about 80-2600 points; 3 levels small)."""
    if family == "uv":
        sizes = [(12, 6), (24, 12), (48, 24)] + ([] if small else [(72, 36)])
        return [uv_sphere(RADIUS_M, s, r) for s, r in sizes]
    if family == "icosphere":
        return [icosphere(k, RADIUS_M) for k in ((1, 2, 3) if small else (1, 2, 3, 4))]
    if family == "irregular":
        out = []
        for n in (162, 642, 1282) if small else (162, 642, 1282, 2562):
            path = folder / f"irregular_{n}.stl"
            _write_stl(irregular_sphere(n, RADIUS_M, seed=1), path)
            out.append(Mesh.load(path))
        return out
    raise ValueError(f"family {family!r}: expected one of {FAMILIES}")


def _write_stl(mesh: Mesh, path: Path) -> None:
    import trimesh

    trimesh.Trimesh(mesh.vert_pos, mesh.face_vert, process=False).export(path)


def closed_form_inflation(p_pa: float, radius_m: float, youngs: float, nu: float) -> float:
    """dR (m) of a Saint Venant-Kirchhoff spherical sheet under gauge pressure p:
    Y (s^2 - 1) / (1 - nu) = p R s, the positive root s."""
    c = p_pa * radius_m * (1.0 - nu) / youngs
    s = 0.5 * (c + math.sqrt(c * c + 4.0))
    return (s - 1.0) * radius_m


def _relax(sim: Simulation, metric, rel_tol: float, chunk_s: float, max_s: float) -> tuple[float, bool]:
    """Step until `metric(sim)` changes by less than rel_tol over a chunk three times in
    a row, at most to max_s: (the metric, whether it settled)."""
    n = max(1, int(round(chunk_s / sim.model.dt_s)))
    last, calm = metric(sim), 0
    while sim.time < max_s:
        sim.step(n)
        now = metric(sim)
        calm = calm + 1 if abs(now - last) <= rel_tol * abs(now) else 0
        last = now
        if calm >= 3:
            break
    return last, calm >= 3


def _stable_dt(scene: Scene) -> float:
    return 0.5 * compile_scene(scene).dt_stable_s


def _r_eq(volume: float) -> float:
    return (3.0 * volume / (4.0 * math.pi)) ** (1.0 / 3.0)


def pressure_sphere(mesh: Mesh) -> dict:
    """A free sphere inflated by PRESSURE_PA against the membrane, relaxed: dR of its
    volume-equivalent radius against the closed form."""
    drag = 2.0 * math.sqrt(YOUNGS_N_PER_M * MASS_KG / (4 * math.pi * RADIUS_M**2)) / RADIUS_M  # about critical
    scene = Scene(
        mesh=mesh,
        masses=Masses(total_kg=MASS_KG),
        forces=(Membrane(YOUNGS_N_PER_M, poisson_ratio=POISSON), Pressure(PRESSURE_PA), Damping(drag_n_s_per_m3=drag)),
        dt_s=1.0,
        duration_s=1e6,
    )
    scene = _with_dt(scene)
    sim = Simulation(compile_scene(scene))
    r0 = _r_eq(sim.volume)
    r, settled = _relax(sim, lambda s: _r_eq(s.volume) - r0, 1e-7, 0.02, 5.0)
    want = closed_form_inflation(PRESSURE_PA, RADIUS_M, YOUNGS_N_PER_M, POISSON)
    return {
        "oracle": "pressure_sphere",
        "nvert": mesh.nvert,
        "measured": r,
        "predicted": want,
        "rel_error": abs(r - want) / want,
        "unit": "m",
        "edge_m": _edge(mesh),
        "settled": settled,
    }


def _with_dt(scene: Scene) -> Scene:
    return dataclasses.replace(scene, dt_s=_stable_dt(scene))


def _edge(mesh: Mesh) -> float:
    p = mesh.vert_pos[mesh.face_vert]
    return float(np.linalg.norm(p[:, 1] - p[:, 0], axis=1).mean())


def hanging_sphere(mesh: Mesh, incompressible: bool = False) -> dict:
    """The sphere hanging from its nailed upper half under gravity, inflated by
    HANGING_PRESSURE_PA (a balloon: in tension everywhere), relaxed: the descent (m)
    of its bottom, the mass-weighted mean over the points within about 0.05 m of the
    lowest point. `incompressible`: filled and held at constant volume instead of
    inflated; parts of it are then compressed, and a membrane without bending
    stiffness wrinkles there at the scale of the mesh (reported, not an oracle)."""
    drag = 2.0 * math.sqrt(HANGING_YOUNGS_N_PER_M * MASS_KG / (4 * math.pi * RADIUS_M**2)) / RADIUS_M
    c = mesh.vert_pos.mean(axis=0)
    load = (Volume(),) if incompressible else ()
    scene = Scene(
        mesh=mesh,
        masses=Masses(total_kg=MASS_KG),
        regions={"upper_half": HalfSpace((c[0], c[1], c[2] - 1e-9 * RADIUS_M), (0.0, 0.0, 1.0))},
        forces=(Gravity(), Membrane(HANGING_YOUNGS_N_PER_M, poisson_ratio=POISSON), Damping(drag_n_s_per_m3=drag))
        + (() if incompressible else (Pressure(HANGING_PRESSURE_PA),)),
        constraints=(Nailed("upper_half"),) + load,
        dt_s=1.0,
        duration_s=1e6,
    )
    scene = _with_dt(scene)
    sim = Simulation(compile_scene(scene))
    rest = mesh.vert_pos
    bottom = rest[:, 2] < c[2] - 0.11 / 0.12 * RADIUS_M
    mass = sim.model.arrays.vert_mass[bottom]

    def descent(s):
        return float(mass @ (rest[bottom, 2] - s.vert_pos[bottom, 2]) / mass.sum())

    sag, settled = _relax(sim, descent, 1e-8, 0.05, 10.0)
    return {
        "oracle": "hanging_sphere_incompressible" if incompressible else "hanging_sphere",
        "nvert": mesh.nvert,
        "measured": sag,
        "predicted": None,
        "rel_error": None,
        "unit": "m",
        "edge_m": _edge(mesh),
        "settled": settled,
    }


def patch_test(n: int, seed: int) -> dict:
    """A flat irregular patch (unit square, n x n points perturbed) stretched uniformly
    by 5% x 3% with shear: the largest interior force against Y l eps."""
    from scipy.spatial import Delaunay

    g = np.linspace(0.0, 1.0, n)
    p = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    inner = (p > 0).all(1) & (p < 1).all(1)
    p[inner] += np.random.default_rng(seed).uniform(-0.3, 0.3, (inner.sum(), 2)) / (n - 1)
    mesh = Mesh.from_arrays(np.c_[p, np.zeros(len(p))], Delaunay(p).simplices)
    model = compile_scene(
        Scene(mesh=mesh, masses=Masses(total_kg=1.0), forces=(Membrane(YOUNGS_N_PER_M, poisson_ratio=POISSON),))
    )
    F = np.array([[1.05, 0.02, 0.0], [0.01, 0.97, 0.0], [0.0, 0.0, 1.0]])
    f = internal_forces(model.arrays, mesh.vert_pos @ F.T, np.zeros((0, 3)))
    scale = YOUNGS_N_PER_M * 0.05 / (n - 1)
    resid = float(np.abs(f[inner]).max())
    return {
        "oracle": "patch_test",
        "nvert": mesh.nvert,
        "measured": resid / scale,
        "predicted": 0.0,
        "rel_error": resid / scale,
        "unit": "interior force / (Y l eps)",
        "edge_m": 1.0 / (n - 1),
    }


def free_body(mesh: Mesh, steps: int, energy_steps: int) -> list[dict]:
    """A free, undamped incompressible sphere set moving from rest shape with a random
    velocity field (0.05 m/s, tangent to the volume constraint), symplectic Euler."""
    base = Scene(
        mesh=mesh,
        masses=Masses(total_kg=MASS_KG),
        forces=(Membrane(YOUNGS_N_PER_M, poisson_ratio=POISSON),),
        constraints=(Volume(),),
        dt_s=1.0,
        duration_s=1e6,
    )
    dt = _stable_dt(base)
    from ..mesh import volume_gradient

    m = compile_scene(base).arrays.vert_mass[:, None]
    g = volume_gradient(mesh.vert_pos, mesh.face_vert)
    v0 = 0.05 * np.random.default_rng(11).standard_normal((mesh.nvert, 3))
    v0 -= (g * v0).sum() / (g * g / m).sum() * g / m  # no volume rate: the constraint holds from the start

    def started(h):
        sim = Simulation(compile_scene(dataclasses.replace(base, dt_s=h)))
        sim.set_state(vert_pos=mesh.vert_pos, vert_vel=v0, time_s=0.0)
        return sim

    def momenta(sim):
        return (m * sim.vert_vel).sum(0), (m * np.cross(sim.vert_pos, sim.vert_vel)).sum(0)

    p_scale = float((m * np.abs(v0)).sum())
    L_scale = float(np.linalg.norm(m * np.cross(mesh.vert_pos - mesh.vert_pos.mean(0), v0), axis=1).sum())
    rows, drift = [], {}
    for h in (dt, dt / 2, dt / 4):
        sim = started(h)
        p0, L0 = momenta(sim)
        if h == dt:
            sim.step(10)
            net = net_internal(sim.vert_pos, internal_forces(sim.model.arrays, sim.vert_pos, np.zeros((0, 3))))
            rows.append(
                _row(
                    "free_body_net_force",
                    mesh,
                    float(np.abs(net["net_force_n"]).max() / net["sum_abs_force_n"]),
                    0.0,
                    "of sum |F|",
                )
            )
            rows.append(
                _row(
                    "free_body_net_moment",
                    mesh,
                    float(np.abs(net["net_moment_n_m"]).max() / net["sum_abs_moment_n_m"]),
                    0.0,
                    "of sum |r x F|",
                )
            )
            sim.step(steps - 10)
            p1, _ = momenta(sim)
            rows.append(
                _row(
                    "free_body_momentum",
                    mesh,
                    float(np.abs(p1 - p0).max() / p_scale),
                    0.0,
                    f"drift of sum m v over {steps} steps, of sum m |v|",
                )
            )
            sim = started(h)
        sim.step(int(round(steps * dt / h)))
        drift[h] = float(np.abs(momenta(sim)[1] - L0).max() / L_scale)
    ratios = [
        drift[dt / 2] / drift[dt] if drift[dt] else None,
        drift[dt / 4] / drift[dt / 2] if drift[dt / 2] else None,
    ]
    rows.append(
        {
            **_row(
                "free_body_angular_momentum",
                mesh,
                drift[dt],
                0.0,
                f"drift over {steps * dt:.3g} s at h = {dt:.3g} s, of sum m |r x v|",
            ),
            "drift_by_dt": {f"{h:.4g}": d for h, d in drift.items()},
            "drift_ratio_half_step": ratios,
        }
    )
    # energy over energy_steps at two steps: symplectic Euler's O(h) oscillation around a
    # mean that SHAKE's projection keeps (no drift)
    change = {}
    for h in (dt, dt / 2):
        sim = started(h)
        e0 = sim.kinetic_energy + sim.elastic_energy
        n, chunk = 200, max(1, int(round(energy_steps * dt / h)) // 200)
        e = np.empty(n)
        for k in range(n):
            sim.step(chunk)
            e[k] = sim.kinetic_energy + sim.elastic_energy
        change[h] = (float((e[-n // 4 :].mean() - e[: n // 4].mean()) / e0), float((e.max() - e.min()) / e0))
    rows.append(
        {
            **_row(
                "free_body_energy",
                mesh,
                change[dt][0],
                0.0,
                f"change of the energy's mean from the first to the last quarter of {energy_steps} steps, "
                f"of the initial energy",
            ),
            "change_by_dt": {f"{h:.4g}": c[0] for h, c in change.items()},
            "spread_by_dt": {f"{h:.4g}": c[1] for h, c in change.items()},
            "change_ratio_half_step": change[dt / 2][0] / change[dt][0] if change[dt][0] else None,
        }
    )
    return rows


def _row(oracle, mesh, measured, predicted, unit) -> dict:
    return {
        "oracle": oracle,
        "mesh_family": None,
        "nvert": mesh.nvert,
        "measured": measured,
        "predicted": predicted,
        "rel_error": abs(measured - predicted),
        "unit": unit,
    }


def _order(rows: list[dict]) -> float | None:
    """Observed spatial order of the relative error against the mean edge, least squares in log-log."""
    ok = [r for r in rows if r["rel_error"] and r["rel_error"] > 0]
    if len(ok) < 2:
        return None
    x = np.log([r["edge_m"] for r in ok])
    y = np.log([r["rel_error"] for r in ok])
    return float(np.polyfit(x, y, 1)[0])


def run(out_dir, small: bool = False) -> dict:
    t0 = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[dict] = []
    order = {}
    with tempfile.TemporaryDirectory() as tmp:
        meshes = {f: family_meshes(f, small, Path(tmp)) for f in FAMILIES}
        for fam, ms in meshes.items():
            pr = [{**pressure_sphere(m), "mesh_family": fam} for m in ms]
            order[fam] = _order(pr)
            rows += pr
        # the small version hangs each family's finest mesh only, against the finest icosphere
        hang = {
            fam: [{**hanging_sphere(m), "mesh_family": fam} for m in (ms[-1:] if small else ms)]
            for fam, ms in meshes.items()
        }
        ref_mesh = meshes["icosphere"][-1] if small else icosphere(5, RADIUS_M)
        ref = hang["icosphere"][-1]["measured"] if small else hanging_sphere(ref_mesh)["measured"]
        for hs in hang.values():
            for h in hs:
                h.update(predicted=ref, rel_error=abs(h["measured"] - ref) / ref)
            rows += hs
        rows.append({**hanging_sphere_ref_row(ref_mesh, ref)})
        incompressible = (
            {}
            if small
            else {fam: hanging_sphere(ms[-1], incompressible=True)["measured"] for fam, ms in meshes.items()}
        )
        rows += [
            {
                "oracle": "hanging_sphere_incompressible",
                "mesh_family": fam,
                "nvert": meshes[fam][-1].nvert,
                "measured": v,
                "predicted": None,
                "rel_error": None,
                "unit": "m",
            }
            for fam, v in incompressible.items()
        ]
        for n, seed in ((5, 1), (9, 2), (17, 3)):
            rows.append({**patch_test(n, seed), "mesh_family": "flat_irregular"})
        fb = free_body(icosphere(2, RADIUS_M), 1000 if small else 10_000, 100_000)
        rows += [{**r, "mesh_family": "icosphere"} for r in fb]
    from .stability.tables import table1

    t1 = table1()
    rows.append(
        {
            "oracle": "paper_table1",
            "mesh_family": "three_point",
            "nvert": 3,
            "measured": t1["max_abs_error"],
            "predicted": 0.0,
            "rel_error": t1["max_abs_error"],
            "unit": "largest |eigenvalue error|",
        }
    )
    finest = {fam: hang[fam][-1]["measured"] for fam in FAMILIES}
    spread = (max(finest.values()) - min(finest.values())) / (sum(finest.values()) / len(finest))
    inc = list(incompressible.values()) or [math.nan]
    res = {
        "rows": rows,
        "order": order,
        "hanging_finest_spread": spread,
        "incompressible_spread": (max(inc) - min(inc)) / (sum(inc) / len(inc)),
        "hanging_finest": {fam: {"nvert": hang[fam][-1]["nvert"], "sag_m": v} for fam, v in finest.items()},
        "runtime_s": time.perf_counter() - t0,
        "small": small,
    }
    write_json(out / "verification.json", res)
    _write_text(out / "verification.md", markdown(res))
    plot(out / "verification.png", res)
    return res


def hanging_sphere_ref_row(mesh: Mesh, sag: float) -> dict:
    return {
        "oracle": "hanging_sphere_reference",
        "mesh_family": "icosphere",
        "nvert": mesh.nvert,
        "measured": sag,
        "predicted": None,
        "rel_error": None,
        "unit": "m",
        "edge_m": _edge(mesh),
    }


def markdown(res: dict) -> str:
    lines = [
        "# Verification of the continuum formulation",
        "",
        f"Runtime {res['runtime_s']:.1f} s{' (small version)' if res['small'] else ''}.",
        "",
        "| oracle | mesh family | points | measured | predicted | relative error | unit |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in res["rows"]:

        def f(v):
            return "-" if v is None else f"{v:.6g}"

        lines.append(
            f"| {r['oracle']} | {r['mesh_family']} | {r['nvert']} | {f(r['measured'])} | "
            f"{f(r['predicted'])} | {f(r['rel_error'])} | {r.get('unit', '')} |"
        )
    lines += [
        "",
        "Observed spatial order of the pressure sphere's error (against the mean edge): "
        + ", ".join(f"{k} {v:.2f}" if v is not None else f"{k} -" for k, v in res["order"].items())
        + ".",
        "",
        "Hanging sphere at each family's finest level: "
        + ", ".join(f"{k} {v['sag_m'] * 1e3:.3f} mm ({v['nvert']} points)" for k, v in res["hanging_finest"].items())
        + f"; spread {100 * res['hanging_finest_spread']:.2f}% of their mean.",
    ]
    if not res["small"]:
        lines += [
            "",
            "The same sphere filled and held at constant volume instead of inflated (not an oracle): "
            f"spread {100 * res['incompressible_spread']:.1f}% across the families at their finest level. "
            "Parts of it are in compression, where a membrane without bending stiffness has no unique "
            "shape at the scale of the mesh.",
        ]
    return "\n".join(lines) + "\n"


def plot(path: Path, res: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for oracle, ax in zip(("pressure_sphere", "hanging_sphere"), axes):
        for fam in FAMILIES:
            rs = [r for r in res["rows"] if r["oracle"] == oracle and r["mesh_family"] == fam and r["rel_error"]]
            if rs:
                ax.loglog([r["nvert"] for r in rs], [r["rel_error"] for r in rs], "o-", label=fam)
        ax.set_xlabel("points")
        ax.set_ylabel("relative error")
        ax.set_title(
            {
                "pressure_sphere": "pressurised sphere vs closed form",
                "hanging_sphere": "hanging balloon's bottom vs fine icosphere",
            }[oracle]
        )
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    _save_figure(fig, path, dpi=110)
    plt.close(fig)
