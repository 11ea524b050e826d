"""Continuum volume and drag terms (issue 11, items 4 and 5): a uniform pressure load
(`Pressure`), a soft volume of a bulk modulus (`SoftVolume(bulk_modulus_pa=...)`) and a
drag per area (`Damping(drag_n_s_per_m3=...)`), each the same material on every mesh.

Two mesh families throughout: icospheres (nearly uniform triangles) and UV spheres
(cells that shrink toward the poles), at comparable point counts."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import forces_at

from hybrid.mesh import icosphere, uv_sphere, vertex_area
from hybrid.mesh import volume as face_volume
from hybrid.model import compile_scene
from hybrid.scene import Damping, Masses, Pressure, Scene, SoftVolume
from hybrid.simulation import Simulation
from hybrid.step import S_PRESSURE

R = 0.1
MESHES = {"icosphere": lambda: icosphere(2, R), "uv_sphere": lambda: uv_sphere(R, 24, 12)}


def _forces(model, pos):
    force, state = forces_at(model, pos)
    return force, float(state.scal[S_PRESSURE])


def _check_gradient(model, energy, pos, rng, nprobe=12):
    """F = -dE/dx by central differences on nprobe random coordinates."""
    force, _ = _forces(model, pos)
    eps = 1e-7 * R
    scale = np.abs(force).max()
    for _ in range(nprobe):
        i, a = rng.integers(model.mesh.nvert), rng.integers(3)
        plus, minus = pos.copy(), pos.copy()
        plus[i, a] += eps
        minus[i, a] -= eps
        fd = -(energy(plus) - energy(minus)) / (2 * eps)
        # central differences: error ~ eps^2 E''' + roundoff E eps_mach / eps
        assert fd == pytest.approx(force[i, a], abs=1e-6 * scale)


@pytest.mark.parametrize("family", MESHES)
def test_the_fill_and_the_load_are_minus_the_gradient_of_their_energies(family):
    """Soft volume of bulk modulus K and a pressure load p: E = K (V - V0)^2 / (2 V0) - p V;
    the readout is the fill's pressure -K (V - V0) / V0; net force zero."""
    mesh = MESHES[family]()
    K, p = 2e4, 300.0
    model = compile_scene(
        Scene(mesh=mesh, masses=Masses(total_kg=1.0), forces=(SoftVolume(bulk_modulus_pa=K), Pressure(p)))
    )
    v0 = mesh.volume()
    rng = np.random.default_rng(3)
    pos = mesh.vert_pos * 1.02 + rng.normal(scale=1e-3, size=mesh.vert_pos.shape)

    def energy(x):
        v = face_volume(x, mesh.face_vert)
        return K * (v - v0) ** 2 / (2 * v0) - p * v

    _check_gradient(model, energy, pos, rng)
    force, p_fill = _forces(model, pos)
    v = face_volume(pos, mesh.face_vert)
    assert p_fill == pytest.approx(-K * (v - v0) / v0, rel=1e-12)
    assert np.abs(force.sum(axis=0)).max() <= 1e-12 * np.abs(force).sum()


@pytest.mark.parametrize("family", MESHES)
def test_a_pressure_load_compresses_the_fill_by_dp_over_k(family):
    """A compressible sphere (bulk modulus K) under an external pressure dp (a
    `Pressure` of -dp), damped by drag to rest: dV / V0 = -dp / K, the closed form.
    Equilibrium asks only that the fill's pressure balance the load, and both act
    on the mesh's own volume, so no discretisation error remains, on either family."""
    mesh = MESHES[family]()
    K, dp = 1e5, 2000.0
    # radial mode: w^2 = 12 pi K R / M ~ 3.8e5 /s^2; drag b A ~ 2 w M damps it near critically
    scene = Scene(
        mesh=mesh,
        masses=Masses(total_kg=1.0),
        dt_s=1e-4,
        forces=(SoftVolume(bulk_modulus_pa=K), Pressure(-dp), Damping(drag_n_s_per_m3=1e4)),
    )
    sim = Simulation(compile_scene(scene))
    sim.step(1000)  # 0.1 s: the radial mode has decayed by e^-60
    v0 = mesh.volume()
    rel = (sim.volume - v0) / v0
    assert rel == pytest.approx(-dp / K, rel=1e-8)
    assert sim.pressure == pytest.approx(dp, rel=1e-8)  # the fill carries the load


def test_the_same_drag_damps_a_translation_at_the_same_rate_on_every_mesh():
    """A free sphere of area density rho moving uniformly, drag b per area: each point
    obeys m_i v' = -b A_i v with m_i = rho A_i, so v decays at b / rho on any mesh
    (symplectic Euler: by (1 - h b / rho) per step); the total drag force per area is
    b v. The paper's coefficient per point, the same c on both meshes, decays at
    rates that differ with the point count."""
    rho, b, h, n = 2.0, 50.0, 1e-3, 40
    v0 = np.array([0.01, -0.02, 0.03])
    rates, paper_rates = {}, {}
    for family, make in MESHES.items():
        mesh = make()
        for drag in ("continuum", "paper"):
            damping = Damping(drag_n_s_per_m3=b) if drag == "continuum" else Damping(coef_n_s_per_m=0.01)
            sim = Simulation(
                compile_scene(
                    Scene(
                        formulation=drag,
                        mesh=mesh,
                        dt_s=h,
                        forces=(damping,),
                        masses=Masses(density_kg_per_m2={"all": rho}),
                    )
                )
            )
            sim.set_state(vert_vel=np.tile(v0, (mesh.nvert, 1)))
            sim.step(1)
            if drag == "continuum":
                area = vertex_area(mesh.vert_pos, mesh.face_vert).sum()
                np.testing.assert_allclose(-sim.vert_force.sum(axis=0) / area, b * v0, rtol=1e-12)
            sim.step(n - 1)
            rate = -np.log(sim.vert_vel / v0) / (n * h)
            (rates if drag == "continuum" else paper_rates)[family] = rate
    for rate in rates.values():
        np.testing.assert_allclose(rate, -np.log(1 - h * b / rho) / h, rtol=1e-10)
    assert abs(paper_rates["icosphere"].mean() / paper_rates["uv_sphere"].mean() - 1) > 0.2
