"""Table 3 and the stability map: the perturbed icosahedron relaxing to equilibrium.

Twelve points of mass m on an icosahedron, each moved along its own random
direction and released at rest (explicit Euler, elastic force and viscosity
only); `relax` counts the steps to equilibrium, `table3` finds the largest h
still reaching it, `stability_map` scans (h, k) against the three-point theory.
"""

from __future__ import annotations

import math

import numpy as np

from hybrid.errors import SimulationDiverged
from hybrid.mesh import Mesh, icosahedron
from hybrid.model import compile_scene
from hybrid.scene import Damping, Masses, MassSpring, Scene, ShapeMemory
from hybrid.simulation import Simulation

from .numerics import largest_true, no_runaway_check
from .tables import K_UNIT, KV_UNIT, M_UNIT, MODELS, rho_table1

__all__ = ["EQ_TOL", "icosahedron_scene", "perturbation", "relax", "table3", "stability_map"]

EQ_TOL = 1e-6  # equilibrium: max |v| <= tol l0 sqrt(k/m) and max |F| <= tol k l0


def icosahedron_scene(model: str, k=K_UNIT, kv=KV_UNIT, m=M_UNIT, h=1.0) -> Scene:
    """12 points of mass m on an icosahedron of circumradius 1 (edge l0 = 1.0515),
    elastic force of the unified weight k (k_sm = k, k_ms = 2k/3) and viscosity kv;
    explicit Euler (eq. 4); nothing nailed, no volume, no gravity."""
    force = ShapeMemory(k) if model == "shape_memory" else MassSpring(2.0 * k / 3.0)
    return Scene(
        formulation="paper",
        mesh=icosahedron(1.0),
        masses=Masses(per_vertex_kg=(m,) * 12),
        forces=(force, Damping(coef_n_s_per_m=kv)),
        dt_s=h,
        integrator="explicit_euler",
        name=f"icosahedron_{model}",
    )


def perturbation(mesh: Mesh, amplitude: float, seed: int = 0) -> np.ndarray:
    """(nvert, 3): each point moved by amplitude * l0 along its own direction drawn
    uniformly on the unit sphere (numpy default_rng(seed)); l0 = mean edge length."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=mesh.vert_pos.shape)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return amplitude * mesh.edge_length_mean() * u


def shape_error(x, rest):
    """Largest distance to the rest shape after the best rigid alignment (Kabsch)."""
    a, b = x - x.mean(0), rest - rest.mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1, 1, d]) @ vt
    return float(np.linalg.norm(a @ rot - b, axis=1).max())


def relax(model, x0, *, k=K_UNIT, m=M_UNIT, tol=EQ_TOL, max_time=3000.0, chunk=100) -> dict:
    """Run from positions x0 at rest until equilibrium: max |v| <= tol l0 sqrt(k/m)
    and max |F| <= tol k l0 (F: elastic + viscous force of the step). Returns
    {"outcome": "equilibrium" | "diverged" | "no_steady_state", "iterations": n,
     "shape_error_l0": e} within max_time (in steps: max_time / h). Diverged: non-finite, or a point 100 l0 from the centroid."""
    sim = Simulation(no_runaway_check(model))
    max_steps = int(math.ceil(max_time / model.dt_s))
    l0 = model.mesh.edge_length_mean()
    vtol, ftol = tol * l0 * math.sqrt(k / m), tol * k * l0
    sim.set_state(vert_pos=x0)
    free = model.arrays.vert_free > 0

    def done():
        v = np.abs(sim.vert_vel[free]).max()
        f = np.abs(sim.vert_force[free]).max()
        return v <= vtol and f <= ftol

    def blown():
        x = sim.vert_pos
        return not np.all(np.isfinite(x)) or np.abs(x - x.mean(0)).max() > 100 * l0

    try:
        while sim.steps_done < max_steps:
            saved = dict(vert_pos=sim.vert_pos.copy(), vert_vel=sim.vert_vel.copy(), time_s=sim.time)
            sim.step(min(chunk, max_steps - sim.steps_done))
            if blown():
                return {"outcome": "diverged", "iterations": sim.steps_done, "shape_error_l0": None}
            if done():  # find the first step of the chunk that meets the tolerance
                sim.set_state(**saved)
                while True:
                    sim.step(1)
                    if done():
                        break
                return {
                    "outcome": "equilibrium",
                    "iterations": sim.steps_done,
                    "shape_error_l0": shape_error(sim.vert_pos, model.arrays.vert_rest) / l0,
                }
    except SimulationDiverged:
        return {"outcome": "diverged", "iterations": sim.steps_done, "shape_error_l0": None}
    return {"outcome": "no_steady_state", "iterations": sim.steps_done, "shape_error_l0": None}


def table3(*, small=False, seeds=tuple(range(10))) -> dict:
    grid = np.arange(0.1, 6.0 + 1e-9, 0.5 if small else 0.1)
    n_bisect = 3 if small else 7
    max_time = 1000.0 if small else 10000.0
    seeds = seeds[:1] if small else seeds
    rows = []
    for model_name in MODELS:
        base = compile_scene(icosahedron_scene(model_name))
        for amp in (0.3, 0.7):
            per_seed = []
            for seed in seeds:
                x0 = base.mesh.vert_pos + perturbation(base.mesh, amp, seed)

                def ok(h):
                    return relax(base.with_dt(h), x0, max_time=max_time)["outcome"] == "equilibrium"

                h_max, h_fail = largest_true(ok, grid, n_bisect, from_top=True)
                at1 = relax(base.with_dt(1.0), x0, max_time=max_time)
                per_seed.append(
                    {
                        "seed": seed,
                        "h_max": h_max,
                        "first_failure_h": h_fail,
                        "iterations_at_h1": at1["iterations"] if at1["outcome"] == "equilibrium" else None,
                        "shape_error_l0_at_h1": at1["shape_error_l0"],
                    }
                )
            hm = min(p["h_max"] for p in per_seed)
            its = [p["iterations_at_h1"] for p in per_seed if p["iterations_at_h1"] is not None]
            errs = [p["shape_error_l0_at_h1"] for p in per_seed if p["shape_error_l0_at_h1"] is not None]
            rows.append(
                {
                    "model": model_name,
                    "perturbation": amp,
                    "h_max": hm,
                    "iterations": int(np.median(its)) if its else None,
                    "h_max_median_over_seeds": float(np.median([p["h_max"] for p in per_seed])),
                    "shape_error_l0_at_h1_max": max(errs) if errs else None,
                    "paper_h_max": {
                        ("mass_spring", 0.3): 3.8,
                        ("mass_spring", 0.7): 1.7,
                        ("shape_memory", 0.3): 4.0,
                        ("shape_memory", 0.7): 2.6,
                    }[(model_name, amp)],
                    "seeds": per_seed,
                }
            )
    return {
        "rows": rows,
        "setup": {
            "mesh": "icosahedron, circumradius 1, l0 = mean edge = 1.0515",
            "m": M_UNIT,
            "kv": KV_UNIT,
            "k_unified": K_UNIT,
            "k_ms": 2 * K_UNIT / 3,
            "k_sm": K_UNIT,
            "integrator": "explicit_euler",
            "forces": "elastic + viscosity only",
            "perturbation": "x_i += a l0 u_i, u_i uniform random unit vectors, seeds " + str(list(seeds)),
            "equilibrium": f"max|v| <= {EQ_TOL} l0 sqrt(k/m) and max|F| <= {EQ_TOL} k l0",
            "iterations": "median over seeds at h = 1, steps to equilibrium",
            "h_max": f"largest h on the grid {grid[0]:.1f}:{grid[1] - grid[0]:.1f}:{grid[-1]:.1f} reaching "
            f"equilibrium within t = {max_time:g} (scanning down from the top), refined by "
            f"{n_bisect} bisections; the minimum over seeds",
        },
    }


# ---------------------------------------------------------------- beyond: map


def stability_map(*, small=False) -> dict:
    hs = np.linspace(0.25, 6.0, 6 if small else 24)
    ks = np.geomspace(0.005, 0.5, 5 if small else 24)
    max_time = 500.0 if small else 2000.0
    out = {"h": hs.tolist(), "k": ks.tolist(), "perturbation": 0.3, "max_time": max_time, "m": M_UNIT, "kv": KV_UNIT}
    for model_name in MODELS:
        grid = np.zeros((ks.size, hs.size), int)  # 1 equilibrium, 0 no steady state, -1 diverged
        theory = np.zeros((ks.size, hs.size), bool)
        for i, k in enumerate(ks):
            base = compile_scene(icosahedron_scene(model_name, k=k))
            x0 = base.mesh.vert_pos + perturbation(base.mesh, 0.3, 0)
            for j, h in enumerate(hs):
                r = relax(base.with_dt(h), x0, k=k, max_time=max_time)
                grid[i, j] = {"equilibrium": 1, "no_steady_state": 0, "diverged": -1}[r["outcome"]]
                theory[i, j] = rho_table1(model_name, h, k, KV_UNIT, M_UNIT) < 1.0
        out[model_name] = {
            "outcome": grid.tolist(),
            "three_point_stable": theory.tolist(),
            "agreement": float(np.mean((grid == 1) == theory)),
        }
    return out
