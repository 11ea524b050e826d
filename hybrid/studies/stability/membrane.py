"""The stability study beyond the paper: the real breathing membrane.

The spectrum of the linearized step of the 80-point breathing membrane (the
breathing scene without its rigid part) and the largest stable h it
predicts, against the largest h observed in runs; and the smallest damping
below which the non-conservative shape memory excites itself.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hybrid.errors import HybridError
from hybrid.model import compile_scene
from hybrid.resolve import resolve_scene
from hybrid.scene import Damping
from hybrid.simulation import Simulation

from .numerics import bisect, largest_true, step_jacobian

__all__ = ["breathing_membrane_scene", "membrane_spectrum", "self_excitation"]


def breathing_membrane_scene(critical_fraction: float | None = None):
    """The breathing scene's 80-point membrane without its rigid part, its
    muscles off (linearization about the rest shape, which is then an equilibrium)."""
    sc = resolve_scene("breathing_paper")
    sc = dataclasses.replace(sc, rigid=None).without("muscle", "muscle_insertion")
    if critical_fraction is not None:
        sc = dataclasses.replace(
            sc,
            forces=tuple(
                dataclasses.replace(f, critical_fraction=critical_fraction) if isinstance(f, Damping) else f
                for f in sc.forces
            ),
        )
    return sc


def membrane_rho(model, h, free):
    sim = Simulation(model.with_dt(h))
    l0 = model.mesh.edge_length_mean()
    jac = step_jacobian(sim, free, dx=1e-7 * l0, dv=1e-4 * l0)
    return float(np.abs(np.linalg.eigvals(jac)).max()), jac


def observed_stable(model, h, *, seconds=1.0, amp=1e-3, seed=0) -> bool:
    """A run from a small random displacement (amp m per free point) stays finite
    and ends closer to rest than it started."""
    sim = Simulation(model.with_dt(h))
    free = model.arrays.vert_free > 0
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(int(free.sum()), 3))
    d *= amp / np.linalg.norm(d, axis=1, keepdims=True)
    x = sim.vert_pos.copy()
    x[free] += d
    sim.set_state(vert_pos=x)
    try:
        sim.step(max(50, int(round(seconds / h))))
    except HybridError:
        return False
    dev = np.linalg.norm(sim.vert_pos[free] - model.arrays.vert_rest[free], axis=1).max()
    return bool(np.isfinite(dev) and dev < amp)


def breath_stable(scene, h) -> bool:
    """One breath (4 s) of the membrane-only breathing scene with its muscles, at step h."""
    try:
        sim = Simulation(compile_scene(dataclasses.replace(scene, dt_s=h)))
        sim.step(int(round(4.0 / h)))
        return bool(np.all(np.isfinite(sim.vert_pos)))
    except HybridError:
        return False


def membrane_spectrum(*, small=False) -> dict:
    scene = breathing_membrane_scene()
    model = compile_scene(scene)
    free = np.nonzero(model.arrays.vert_free > 0)[0]
    h0 = model.dt_s
    rho0, jac = membrane_rho(model, h0, free)
    eig = np.linalg.eigvals(jac)
    n_b = 6 if small else 14
    h_pred, _ = largest_true(
        lambda h: membrane_rho(model, h, free)[0] <= 1.0 + 1e-6, [h0 * f for f in (1, 2, 3, 4, 5, 6, 8)], n_b
    )
    grid = [h0 * f for f in (1, 2, 3, 4, 5, 6, 8, 10)]
    h_obs, _ = largest_true(lambda h: observed_stable(model, h, seconds=0.3 if small else 1.0), grid, n_b)
    full = dataclasses.replace(resolve_scene("breathing_paper"), rigid=None)
    h_breath, _ = largest_true(lambda h: breath_stable(full, h), grid, 2 if small else 8)
    coupled = resolve_scene("breathing_paper")
    h_coupled = None
    if not small:
        h_coupled, _ = largest_true(lambda h: breath_stable(coupled, h), grid, 6)
    return {
        "scene": "breathing without rigid part and muscles (linearized about rest)",
        "nfree": int(free.size),
        "dt_s": h0,
        "spectral_radius_at_dt": rho0,
        "eigenvalues_re": eig.real.tolist(),
        "eigenvalues_im": eig.imag.tolist(),
        "h_max_per_point_estimate": model.dt_stable_s,
        "h_max_linearized": h_pred,
        "h_max_observed": h_obs,
        "h_max_observed_breath_membrane_only": h_breath,
        "h_max_observed_breath_coupled": h_coupled,
        "observed_criterion": "1 s from 1 mm random displacements: finite and ends closer to rest; "
        "breath: 4 s with muscles, no SimulationDiverged/ConstraintError",
    }


def self_excitation(*, small=False) -> dict:
    """Smallest critical_fraction keeping the undriven membrane stable, from the
    spectral radius of the linearized step and from runs (kinetic-energy growth)."""
    n_b = 3 if small else 12

    def rho(frac):
        model = compile_scene(breathing_membrane_scene(frac))
        free = np.nonzero(model.arrays.vert_free > 0)[0]
        return membrane_rho(model, model.dt_s, free)[0]

    def lin_stable(frac):
        return rho(frac) <= 1.0 + 1e-9

    def run_stable(frac, seconds=1.0 if small else 8.0):
        model = compile_scene(breathing_membrane_scene(frac))
        sim = Simulation(model)
        free = model.arrays.vert_free > 0
        rng = np.random.default_rng(1)
        x = sim.vert_pos.copy()
        x[free] += 1e-4 * rng.normal(size=(int(free.sum()), 3))
        sim.set_state(vert_pos=x)
        n = int(round(seconds / model.dt_s))
        ke = []
        try:
            for _ in range(20):
                sim.step(n // 20)
                ke.append(sim.kinetic_energy)
        except HybridError:
            return False
        ke = np.log(np.maximum(ke, 1e-300))
        # growth: the energy of the last quarter above that of the second quarter
        return bool(ke[-5:].mean() < ke[5:10].mean())

    def lowest_stable(pred):
        if pred(0.0):
            return 0.0
        return bisect(lambda frac: not pred(frac), 0.0, 0.3, n_b)[1]

    fr = [0.0, 0.1, 0.3] if small else [0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3]
    return {
        "critical_fraction_min_linearized": lowest_stable(lin_stable),
        "critical_fraction_min_observed": lowest_stable(run_stable),
        "spectral_radius_by_fraction": [{"critical_fraction": f, "spectral_radius": rho(f)} for f in fr],
        "setup": "breathing membrane without rigid part and muscles, symplectic Euler dt 1e-3 s; "
        "runs from 0.1 mm random displacements, excited if ln KE grows between "
        "the second and the last quarter",
    }
