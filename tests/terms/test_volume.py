"""The volume terms (hybrid.terms.volume; paper 4.3 and 6.2): the exact projection, its
pressure readout, and the soft (compressible) volume.

The exact projection solves the cubic V(X* + phi D) = V0 to machine precision,
so what remains of |V - V0| / V0 after a step is the roundoff of V itself: a
sum of nface triple products of size R^3, each rounded to ~eps relative, i.e.
~sqrt(nface) eps ~ 1e-14 at worst for the meshes below. The issue's bound,
1e-12, leaves two orders of margin and still catches any projection that is
merely linearised (a linear step leaves an O(phi^2) error of ~1e-8 here).

Every volume below is recomputed independently of the compiled step: the
step gathers its volume from the one-ring fans (hybrid.terms.volume), the
checks use the per-face formula of hybrid.mesh.volume (numpy) or trimesh.
"""

from __future__ import annotations

import numpy as np
import pytest

from hybrid.implicit_work import no_implicit_work
from hybrid.mesh import uv_sphere
from hybrid.mesh import volume as face_volume
from hybrid.mesh import volume_gradient as face_volume_gradient
from hybrid.model import compile_scene
from hybrid.regions import HalfSpace, Indices
from hybrid.scene import (
    AppliedForce,
    Damping,
    Gravity,
    Masses,
    MassSpring,
    MeshSpec,
    Nailed,
    Scene,
    ShapeMemory,
    SoftVolume,
    Volume,
)
from hybrid.simulation import Simulation
from hybrid.step import S_PRESSURE, membrane_forces
from hybrid.step_work import new_control, new_state, new_work

VOLUME_RTOL = 1e-12  # the bound; see the module docstring for why it is reachable


def nailed_sphere_scene(
    mesh: MeshSpec, *, stiffness=3000.0, dt=1e-3, integrator="symplectic_euler", elastic=None
) -> Scene:
    """A 4 kg sphere (R = 0.12 m) hanging under gravity from its nailed bottom cap,
    incompressible: the test body of the paper, the trunk's abdomen."""
    return Scene(
        formulation="paper",
        mesh=mesh,
        masses=Masses(total_kg=4.0),
        regions={"bottom": HalfSpace((0.0, 0.0, -0.1), (0.0, 0.0, -1.0))},
        forces=(Gravity(), elastic or ShapeMemory(stiffness), Damping(critical_fraction=0.3)),
        constraints=(Nailed("bottom"), Volume()),
        dt_s=dt,
        integrator=integrator,
    )


@pytest.mark.parametrize("integrator", ["symplectic_euler", "explicit_euler"])
def test_volume_exact_every_step_80_point_sphere(integrator):
    """10,000 single steps of the paper's 80-point sphere; V checked after each."""
    model = compile_scene(nailed_sphere_scene(MeshSpec(), integrator=integrator))
    assert model.mesh.nvert == 80 and model.mesh.nface == 156
    face = model.mesh.face_vert
    v0 = face_volume(model.mesh.vert_pos, face)
    sim = Simulation(model)
    nstep = 10_000
    err = np.empty(nstep)
    pressure = np.empty(nstep)
    for k in range(nstep):
        sim.step(1)
        err[k] = abs(face_volume(sim.vert_pos, face) - v0) / v0
        pressure[k] = sim.pressure
    assert sim.steps_done == nstep
    assert err.max() <= VOLUME_RTOL, f"worst step {err.argmax()}: {err.max():.3g}"
    # the run is not trivially at rest: the body sags and the projection works hard
    disp = np.linalg.norm(sim.vert_pos - model.mesh.vert_pos, axis=1).max()
    assert disp > 1e-3  # m (about 7 mm measured)
    assert pressure[-1] > 100.0  # Pa: the hanging body is pressurised (about 250-290 Pa)
    assert sim.term_calls["volume"] == nstep
    # and without the constraint the same body does lose volume
    free = Simulation(compile_scene(nailed_sphere_scene(MeshSpec(), integrator=integrator).without("volume")))
    free.step(1000)
    assert abs(face_volume(free.vert_pos, face) - v0) / v0 > 1e-3


def test_volume_exact_every_step_icosphere_10242():
    """icosphere(5): 10,242 points, 3,000 steps, V checked after every one of them
    (a frame of the compiled loop after each step), after every chunk of 100
    with numpy and trimesh, and for 200 more steps through the public step(1).
    The chunks alternate the serial and the multi-core builds of the step (a
    `Simulation` fixed to each, the state handed over), so both keep the volume
    exact over the run."""
    # 4 kg on 10,242 points: m ~ 3.9e-4 kg. Shape memory k = 3000 N/m gives a
    # per-point bound 2/omega ~ 7e-4 s for symplectic Euler (the model reports
    # ~4.7e-4 s with the damping): dt = 2e-4 s is stable with margin.
    model = compile_scene(nailed_sphere_scene(MeshSpec(generator="icosphere", subdivisions=5), dt=2e-4))
    mesh = model.mesh
    assert mesh.nvert == 10242 and model.arrays.parallel  # above PARALLEL_MIN_VERTS: both builds
    assert model.dt_s < model.dt_stable_s
    face = np.ascontiguousarray(mesh.face_vert)
    v0 = face_volume(mesh.vert_pos, face)
    assert abs(v0 - mesh.to_trimesh().volume) <= 1e-13 * v0
    # one Simulation per build; each chunk restarts the other's state bit for bit (set_state)
    sims = {par: Simulation(model, build="parallel" if par else "serial") for par in (False, True)}
    # 0.6 s simulated. Beside other busy processes (the suite's other worker) the multi-core
    # build is the slower here: 15 ms of CPU a step measured on a loaded machine, 0.7 ms serial
    nstep, chunk = 3_000, 100
    err = np.full(nstep, np.nan)
    err_chunk = []
    pressure = []
    frames = sims[False].frames_buffer(chunk)
    sim = sims[False]
    for c in range(nstep // chunk):
        if c:
            state = sim.get_state()
            sim = sims[c % 2 == 1]
            sim.set_state(state)
        # every step a frame: its points, whose volume numpy computes face by face
        sim.step_frames(np.arange(c * chunk + 1, (c + 1) * chunk + 1), frames)
        assert frames.count == chunk
        err[c * chunk : (c + 1) * chunk] = [abs(face_volume(p, face) - v0) / v0 for p in frames.pos]
        err_chunk.append(abs(face_volume(sim.vert_pos, face) - v0) / v0)
        pressure.append(sim.pressure)
    # each build ran its half of the chunks, and no other
    assert sims[False].builds.summary()["parallel_steps"] == sims[True].builds.summary()["serial_steps"] == 0
    assert sims[False].builds.summary()["serial_steps"] == sims[True].builds.summary()["parallel_steps"] == nstep // 2
    assert not np.isnan(err).any()
    assert err.max() <= VOLUME_RTOL, f"worst step {err.argmax()}: {err.max():.3g}"
    assert max(err_chunk) <= VOLUME_RTOL
    tm = mesh.to_trimesh()
    tm.vertices = np.array(sim.vert_pos)
    assert abs(tm.volume - v0) / v0 <= VOLUME_RTOL
    # moving, not at rest: the sphere sags (about 6 mm at 2 s) under a growing pressure
    disp = np.linalg.norm(sim.vert_pos - mesh.vert_pos, axis=1).max()
    assert disp > 1e-3
    assert min(pressure) > 0.0 and pressure[-1] > 100.0
    # 200 more steps one at a time through the public API
    single = []
    for _ in range(200):
        sim.step(1)
        single.append(abs(face_volume(sim.vert_pos, face) - v0) / v0)
    assert max(single) <= VOLUME_RTOL
    assert sim.steps_done == nstep + 200


def test_volume_constraint_on_the_mass_spring_model():
    """Paper 6.2: the projection applies to any model whose volume is a function of
    the surface points, e.g. a mass-spring network."""
    scene = nailed_sphere_scene(MeshSpec(), elastic=MassSpring(1000.0))
    model = compile_scene(scene)
    assert "mass_spring" in model.terms and "shape_memory" not in model.terms
    face = model.mesh.face_vert
    v0 = face_volume(model.mesh.vert_pos, face)
    sim = Simulation(model)
    err = []
    for _ in range(2000):
        sim.step(1)
        err.append(abs(face_volume(sim.vert_pos, face) - v0) / v0)
    assert max(err) <= VOLUME_RTOL
    assert sim.pressure > 100.0  # Pa (about 1.2 kPa: springs alone hold the shape poorly)
    # the same network without the constraint collapses by a fifth of its volume
    free = Simulation(compile_scene(scene.without("volume")))
    free.step(2000)
    assert (v0 - face_volume(free.vert_pos, face)) / v0 > 0.05


def test_pressure_readout_matches_a_uniform_normal_load():
    """An incompressible sphere under the load -p_ext a_i (a_i = the vertex area
    vector at rest, i.e. p_ext times each vertex's area vector, which equals
    grad_i V for a closed surface): an internal pressure p_ext balances it at
    the rest shape. Started from a random deformation, with strong damping,
    the body must come to rest with p = phi / h^2 within 1% of p_ext.

    The load is dead (fixed directions), and a dead normal load on a sphere
    makes rigid rotations unstable (a rotation by theta meets a torque
    2 p V theta along it): with one nail the body slowly spins up about it.
    Three nails far apart (both poles and a point of the equator) leave no
    rigid motion. At rest the readout exceeds p_ext by O(h^2): the free step
    shrinks the body by h^2 p |a| / m before the projection, whose gradient
    is then smaller by that relative amount twice (measured +3.1e-4).
    """
    p_ext = 500.0  # Pa
    mesh = uv_sphere(0.12)
    area = mesh.vert_area_vector()
    np.testing.assert_allclose(area, mesh.volume_gradient(), atol=1e-15)
    loads = tuple(AppliedForce(Indices((i,)), tuple(-p_ext * area[i]), name=f"load{i}") for i in range(mesh.nvert))
    nails = (0, 79, 40)  # north pole, south pole, a point of the equator
    scene = Scene(
        formulation="paper",
        mesh=mesh,
        masses=Masses(total_kg=4.0),
        regions={"nails": Indices(nails)},
        forces=(ShapeMemory(3000.0), Damping(critical_fraction=1.0)) + loads,
        constraints=(Nailed("nails"), Volume()),
        dt_s=1e-3,
    )
    sim = Simulation(compile_scene(scene))
    edge = mesh.edge_length_mean()
    rng = np.random.default_rng(2)
    kick = rng.normal(scale=0.1 * edge, size=mesh.vert_pos.shape)
    kick[list(nails)] = 0.0
    sim.state.vert_pos[:] += kick
    sim.step(6000)
    assert np.linalg.norm(sim.vert_vel, axis=1).max() < 1e-5  # m/s: at rest
    assert sim.kinetic_energy < 1e-10  # J, after the projection (the free step alone has ~1e-3 J)
    assert np.linalg.norm(sim.vert_pos - mesh.vert_pos, axis=1).max() < 1e-3 * edge
    assert abs(sim.pressure - p_ext) <= 0.01 * p_ext  # the bound
    assert abs(sim.pressure - p_ext) <= 2e-3 * p_ext  # the O(h^2) bias, ~3.1e-4


def _soft_phi(pos, face, v0):
    """phi with V(X + phi grad V(X)) = V0, from an independent cubic.

    V is a homogeneous cubic form, so with g = grad V(X):
    V(X + phi g) = V(X) + phi |g|^2 + phi^2 grad V(g) . X + phi^3 V(g)
    (for a closed surface neither V nor its gradient depends on the origin).
    Returns the real root nearest 0.
    """
    g = face_volume_gradient(pos, face)
    c0 = face_volume(pos, face) - v0
    c1 = float(np.sum(g * g))
    c2 = float(np.sum(face_volume_gradient(g, face) * (pos - pos.mean(axis=0))))
    c3 = face_volume(g, face)
    roots = np.roots([c3, c2, c1, c0])
    real = roots[np.abs(roots.imag) <= 1e-9 * np.abs(roots)].real
    return real[np.argmin(np.abs(real))], g


def test_soft_volume_force_is_the_attraction_to_the_volume_satisfying_points():
    """F_i = k (X_i^target - X_i) = k phi grad_i V, readout p = k phi (Pa), and
    p > 0 (pushing outward) for a compressed body, p < 0 for a dilated one."""
    k = 2e4
    model = compile_scene(
        Scene(formulation="paper", mesh=MeshSpec(), masses=Masses(total_kg=4.0), forces=(SoftVolume(k),))
    )
    mesh = model.mesh
    rng = np.random.default_rng(7)
    for scale, sign in ((0.99, +1), (1.01, -1)):
        state = new_state(model.arrays)
        pos = mesh.vert_pos * scale + rng.normal(scale=1e-3, size=mesh.vert_pos.shape)
        state.vert_pos[:] = pos
        work = new_work(model.arrays, state)
        membrane_forces(model.arrays, state, work, no_implicit_work(model.arrays), new_control(model.arrays), 0.0)
        phi, g = _soft_phi(pos, mesh.face_vert, mesh.volume())
        p = state.scal[S_PRESSURE]
        assert np.sign(p) == sign
        # phi is the root of a cubic whose constant term, V - V0 ~ 3e-2 V0, is a
        # difference of volumes: relative roundoff ~ eps / 3e-2, far below 1e-10
        assert p == pytest.approx(k * phi, rel=1e-10)
        np.testing.assert_allclose(work.vert_force, k * phi * g, rtol=0, atol=1e-10 * np.abs(k * phi * g).max())
        assert (mesh.volume(pos) - mesh.volume()) * sign < 0  # compressed <=> p > 0


@pytest.mark.parametrize("p_ext", [500.0, -500.0])
def test_soft_volume_keeps_the_error_bounded_and_reads_the_pressure(p_ext):
    """A uniform normal load p_ext (inward if > 0) on a compressible sphere.

    grad_i V of a closed surface is its vertex area vector, so the load
    -p_ext grad_i V is balanced by an internal pressure p_ext. The soft term
    is a pressure k phi with phi ~ (V0 - V) / |grad V|^2, so if it carried the
    whole load the static volume error would be p_ext |grad V|^2 / (k V0); a
    damped linear response to a suddenly applied load overshoots its static
    value at most twice. Shape memory takes a small share of a uniform
    compression (its offsets gamma n do not scale), so the soft pressure ends
    a little below p_ext, and the error a little below the static bound.
    """
    from hybrid.mesh import uv_sphere

    mesh = uv_sphere(0.12)
    area = mesh.vert_area_vector()
    v0 = mesh.volume()
    grad2 = float(np.sum(mesh.volume_gradient() ** 2))
    errs = {}
    for k in (2e4, 8e4):
        loads = tuple(AppliedForce(Indices((i,)), tuple(-p_ext * area[i]), name=f"load{i}") for i in range(mesh.nvert))
        scene = Scene(
            formulation="paper",
            mesh=mesh,
            masses=Masses(total_kg=4.0),
            forces=(ShapeMemory(3000.0), Damping(critical_fraction=0.5), SoftVolume(k)) + loads,
        )
        sim = Simulation(compile_scene(scene))
        static = abs(p_ext) * grad2 / (k * v0)
        err = []
        for _ in range(300):
            sim.step(10)
            err.append((mesh.volume(sim.vert_pos) - v0) / v0)
        err = np.array(err)
        assert np.abs(err).max() <= 2.0 * static
        # at rest (3 s, kinetic energy ~1e-9 J): sign and size of pressure and error
        assert sim.kinetic_energy < 1e-6
        assert np.sign(err[-1]) == -np.sign(p_ext)
        assert np.sign(sim.pressure) == np.sign(p_ext)
        assert 0.95 * abs(p_ext) <= abs(sim.pressure) <= abs(p_ext)  # measured 98.7 % (k = 2e4), 99.7 % (8e4)
        assert 0.9 * static <= abs(err[-1]) <= static
        errs[k] = abs(err[-1])
    # a stiffer term, a smaller error: inversely proportional to k to within the shape-memory share
    assert errs[8e4] / errs[2e4] == pytest.approx(0.25, rel=0.05)


def test_cubic_root_nearest_zero_matches_numpy_roots():
    """The projection's allocation-free cubic solver against numpy's companion-
    matrix roots on random cubics spanning nine decades (c1 > 0 as for the
    projection): the real root nearest 0, to 1e-6 relative (np.roots itself is
    only accurate to about sqrt(eps) near multiple roots)."""
    from hybrid.terms.volume import solve_cubic_near_zero

    rng = np.random.default_rng(7)
    for _ in range(5000):
        c = rng.normal(size=4) * 10.0 ** rng.uniform(-6, 3, size=4)
        c[1] = abs(c[1])
        root, status = solve_cubic_near_zero(*c)
        assert status == 0
        ref = np.roots(c[::-1])
        real = ref[np.abs(ref.imag) <= 1e-7 * np.maximum(1.0, np.abs(ref.real))].real
        nearest = real[np.argmin(np.abs(real))]
        assert abs(root - nearest) <= 1e-6 * max(1.0, abs(nearest)), (c, root, real)
