"""The Jacobians implicit Euler solves with (hybrid.terms.tangents, hybrid.implicit):
each against central finite differences of the compiled forces on a small irregular
mesh deformed at random, and the membrane's projection to positive semi-definite."""

import numpy as np
import pytest
from helpers import every_row, no_planes

from hybrid import Damping, HalfSpace, Masses, Membrane, MuscleFibres, RestingTension, Scene
from hybrid.implicit import implicit_forces, implicit_work, newton_caches, newton_product, newton_rows
from hybrid.integrators import IMPLICIT_EULER_ID
from hybrid.mesh import irregular_sphere
from hybrid.model import compile_scene
from hybrid.terms.fibres import MIN_STRETCH, add_muscle_fibres
from hybrid.terms.membrane import add_membrane_serial
from hybrid.terms.tangents import (
    NCACHE,
    NFIB_CACHE,
    NPF_CACHE,
    fibre_cached_product,
    fibre_energy,
    fibre_tangent_cache,
    fibre_tangent_product,
    membrane_tangent_cache,
    membrane_tangent_product,
)

R = 0.12
TENSION = 40.0  # N/m


@pytest.fixture(scope="module")
def model():
    mesh = irregular_sphere(40, R, seed=2)
    return compile_scene(
        Scene(
            mesh=mesh,
            masses=Masses(total_kg=1.0),
            integrator="implicit_euler",
            forces=(
                Membrane(800.0, poisson_ratio=0.3, damping_time_s=0.02),
                MuscleFibres(HalfSpace((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), TENSION, toward_m=(0.0, 0.0, R)),
                RestingTension(tension_n_per_m=25.0, region=HalfSpace((0.0, 0.0, -0.02), (0.0, 0.0, 1.0))),
                Damping(drag_n_s_per_m3=30.0),
            ),
        )
    )


def deformed(model, seed, scale=0.01):
    """The rest shape moved at random by about `scale` m (strains of about 10%)."""
    x = model.arrays.vert_rest
    return x + scale * np.random.default_rng(seed).standard_normal(x.shape)


def sched(model):
    return np.full((model.arrays.sched.kind.shape[0], 3), TENSION)


def columns(n, product):
    """The matrix of a linear map on (n, 3) arrays, column by column."""
    out = np.zeros((3 * n, 3 * n))
    for j in range(3 * n):
        u = np.zeros((n, 3))
        u.flat[j] = 1.0
        out[:, j] = product(u).ravel()
    return out


def finite_difference(fun, x, eps):
    """d fun / d x (3n x 3n) by central differences of step eps."""
    n = x.shape[0]
    out = np.zeros((3 * n, 3 * n))
    for j in range(3 * n):
        xp, xm = x.copy(), x.copy()
        xp.flat[j] += eps
        xm.flat[j] -= eps
        out[:, j] = ((fun(xp) - fun(xm)) / (2.0 * eps)).ravel()
    return out


def rel_error(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


def membrane_force(a, x, v):
    f = np.zeros_like(x)
    add_membrane_serial(a.mem_vert, a.mem_par, a.kv_on, x, v, f)
    return f


def membrane_matrix(a, x, kx, kv, project):
    cache = np.zeros((a.mem_vert.shape[0], NCACHE))
    membrane_tangent_cache(a.mem_vert, a.mem_par, x, cache)

    def product(u):
        y = np.zeros_like(u)
        membrane_tangent_product(a.mem_vert, a.mem_par, cache, project, kx, kv, u, y)
        return y

    return columns(x.shape[0], product), cache


@pytest.mark.parametrize("seed", [0, 1])
def test_the_membrane_hessian_is_minus_the_force_jacobian(model, seed):
    a = model.arrays
    x = deformed(model, seed)
    zero = np.zeros_like(x)
    hess, _ = membrane_matrix(a, x, 1.0, 0.0, False)
    fd = finite_difference(lambda y: membrane_force(a, y, zero), x, 1e-7)
    assert rel_error(-hess, fd) <= 1e-6
    assert np.abs(hess - hess.T).max() <= 1e-12 * np.abs(hess).max()


def test_the_kelvin_voigt_damping_matrix_is_minus_the_velocity_jacobian(model):
    a = model.arrays
    x = deformed(model, 3)
    v = 0.05 * np.random.default_rng(4).standard_normal(x.shape)
    damp, _ = membrane_matrix(a, x, 0.0, 1.0, False)
    fd = finite_difference(lambda w: membrane_force(a, x, w), v, 1e-4)
    assert np.abs(damp).max() > 0
    assert rel_error(-damp, fd) <= 1e-6


@pytest.mark.parametrize("width", [0.0, 0.5], ids=["no_force_length", "force_length"])
def test_the_fibre_hessian_is_minus_the_force_jacobian(model, width):
    a = model.arrays
    x = deformed(model, 5)
    sv = sched(model)
    par = a.fib_par.copy()
    par[:, 4] = width

    def force(y):
        f = np.zeros_like(y)
        add_muscle_fibres(a.fib_vert, par, a.fib_sched, sv, y, f)
        return f

    def product(u):
        y = np.zeros_like(u)
        fibre_tangent_product(a.fib_vert, par, a.fib_sched, sv, x, False, 1.0, u, y)
        return y

    hess = columns(x.shape[0], product)
    assert rel_error(-hess, finite_difference(force, x, 1e-7)) <= 1e-6


@pytest.mark.parametrize("width", [0.0, 0.5], ids=["no_force_length", "force_length"])
def test_triangles_collapsed_along_their_fibres_pull_in_proportion(model, width):
    """Triangles shrunk to 2% (fibre stretch below MIN_STRETCH): the force is minus the work
    function's gradient and the Hessian minus its Jacobian there; a point triangle pulls nothing."""
    a = model.arrays
    sv = sched(model)
    par = a.fib_par.copy()
    par[:, 4] = width
    x = deformed(model, 9, scale=0.002)
    used = set()
    for f in range(0, a.fib_vert.shape[0], 3):
        tri = [int(v) for v in a.fib_vert[f]]
        if used.isdisjoint(tri):
            c = x[tri].mean(axis=0)
            x[tri] = c + 0.02 * (x[tri] - c)
            used.update(tri)
    sq = np.zeros(a.fib_vert.shape[0])
    for k in range(3):
        d = x[a.fib_vert[:, (k + 1) % 3]] - x[a.fib_vert[:, k]]
        sq += par[:, k] * np.sum(d * d, axis=1)
    assert (np.sqrt(sq) < 0.5 * MIN_STRETCH).sum() >= 3

    def force(y):
        f = np.zeros_like(y)
        add_muscle_fibres(a.fib_vert, par, a.fib_sched, sv, y, f)
        return f

    def energy(y):
        return fibre_energy(a.fib_vert, par, a.fib_sched, sv, y)

    def product(u):
        y = np.zeros_like(u)
        fibre_tangent_product(a.fib_vert, par, a.fib_sched, sv, x, False, 1.0, u, y)
        return y

    assert rel_error(-columns(x.shape[0], product), finite_difference(force, x, 1e-8)) <= 1e-6
    grad = np.zeros(x.size)
    for j in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp.flat[j] += 1e-7
        xm.flat[j] -= 1e-7
        grad[j] = (energy(xp) - energy(xm)) / 2e-7
    assert rel_error(-grad.reshape(x.shape), force(x)) <= 1e-6
    tri = a.fib_vert[0]
    one = []  # triangle 0 alone, shrunk to 2% and 1%: its pull halves (a constant pull would not)
    for s in (0.02, 0.01):
        y = x.copy()
        c = model.mesh.vert_pos[tri].mean(axis=0)
        y[tri] = c + s * (model.mesh.vert_pos[tri] - c)
        f = np.zeros_like(y)
        add_muscle_fibres(a.fib_vert[:1], par[:1], a.fib_sched[:1], sv, y, f)
        one.append(np.abs(f).max())
    assert abs(one[1] / one[0] - 0.5) < 1e-9
    x[tri] = x[tri].mean(axis=0)  # a point: no direction, no pull from this triangle
    f_point = force(x)
    x[tri[1]] += 1e-12
    assert np.isfinite(f_point).all() and np.abs(f_point - force(x)).max() < 1e-9


def test_the_newton_matrix_against_finite_differences_of_the_implicit_forces(model):
    """M + h^2 K + h C with every term (membrane, its viscosity, fibres, resting tension, drag),
    unprojected, against M - h^2 dF/dx - h dF/dv: dF/dx at v = 0 (where the
    viscous force's dependence on x, which the Newton matrix leaves out, vanishes)."""
    a = model.arrays
    h = 2e-3
    x = deformed(model, 6)
    sv = sched(model)
    zero = np.zeros_like(x)
    v = 0.05 * np.random.default_rng(7).standard_normal(x.shape)
    face = np.zeros((a.mem_vert.shape[0], NCACHE))
    fib = np.zeros((a.fib_vert.shape[0], NFIB_CACHE))
    pf = np.zeros((a.pf_vert.shape[0], NPF_CACHE))
    # every triangle's rows and no planes, of the types the solve passes: its compiled kernels serve
    newton_caches(a, every_row(a), sv, x, face, fib, pf)

    def product(u):
        y = np.zeros_like(u)
        newton_product(a, every_row(a), face, fib, pf, h, False, u, y, no_planes(a))
        return y

    work = implicit_work(a._replace(integrator=IMPLICIT_EULER_ID))  # the lungs' arrays it reads (none here)

    def forces(y, w):
        f = np.zeros_like(y)
        implicit_forces(a, a, sv, y, w, f, work)
        return f

    newton = columns(x.shape[0], product)
    dfdx = finite_difference(lambda y: forces(y, zero), x, 1e-7)
    dfdv = finite_difference(lambda w: forces(x, w), v, 1e-4)
    mass = np.diag(np.repeat(a.vert_mass, 3))
    expected = mass - h * h * dfdx - h * dfdv
    assert rel_error(newton - mass, expected - mass) <= 1e-6


def test_the_projected_element_hessian_is_psd_and_exact_where_the_exact_one_is(model):
    """Compressed and stretched triangles both: each element's 9 x 9 Hessian, exact
    and projected. The projected one has no negative eigenvalue; where the exact one
    has none, they are equal; where it has one, the projection removed it."""
    a = model.arrays
    x = 0.93 * deformed(model, 9, scale=0.006)  # some triangles compressed, some stretched
    convex = indefinite = 0
    for k in range(a.mem_vert.shape[0]):
        corners = a.mem_vert[k]
        one = a._replace(mem_vert=a.mem_vert[k : k + 1], mem_par=a.mem_par[k : k + 1])
        dofs = (3 * corners[:, None] + np.arange(3)).ravel()
        exact = membrane_matrix(one, x, 1.0, 0.0, False)[0][np.ix_(dofs, dofs)]
        proj = membrane_matrix(one, x, 1.0, 0.0, True)[0][np.ix_(dofs, dofs)]
        scale = np.abs(exact).max()
        ev_exact, ev_proj = np.linalg.eigvalsh(exact), np.linalg.eigvalsh(proj)
        assert ev_proj.min() >= -1e-12 * scale, k
        if ev_exact.min() >= -1e-12 * scale:
            convex += 1
            assert np.abs(proj - exact).max() <= 1e-12 * scale, k
        else:
            indefinite += 1
            assert np.abs(proj - exact).max() > 0.0
    assert convex >= 5 and indefinite >= 5, (convex, indefinite)


def test_the_passive_fibre_hessian_is_minus_the_force_jacobian_and_its_energy():
    """Passive fibres around the z axis on the deformed sphere (stretched triangles and
    slack ones): the exact Hessian against central differences of the compiled force,
    the projected one positive semi-definite, and the compiled energy the numpy one
    (the assembled blocks: tests/test_implicit_matrix.py)."""
    from hybrid import PassiveFibres
    from hybrid.terms.passive_fibres import add_passive_fibres, passive_fibres_energy
    from hybrid.terms.tangents import passive_fibres_energy_kernel, passive_fibres_tangent_product

    mesh = irregular_sphere(40, R, seed=2)
    a = compile_scene(
        Scene(
            mesh=mesh,
            masses=Masses(total_kg=1.0),
            integrator="implicit_euler",
            forces=(Membrane(800.0), PassiveFibres(modulus_n_per_m=600.0, around_axis=(0.0, 0.0, 1.0))),
        )
    ).arrays
    x = deformed(compile_scene(Scene(mesh=mesh, masses=Masses(total_kg=1.0))), 11)
    n = x.shape[0]

    def force(y):
        f = np.zeros_like(y)
        add_passive_fibres(a.pf_vert, a.pf_par, y, f)
        return f

    def matrix(project):
        def product(u):
            y = np.zeros_like(u)
            passive_fibres_tangent_product(a.pf_vert, a.pf_par, x, project, 1.0, u, y)
            return y

        return columns(n, product)

    exact, proj = matrix(False), matrix(True)
    assert np.abs(exact).max() > 0
    assert rel_error(-exact, finite_difference(force, x, 1e-7)) <= 1e-6
    assert np.linalg.eigvalsh(0.5 * (proj + proj.T)).min() >= -1e-12 * np.abs(proj).max()
    energy = passive_fibres_energy_kernel(a.pf_vert, a.pf_par, x)
    assert energy > 0 and energy == pytest.approx(passive_fibres_energy(a.pf_vert, a.pf_par, x), rel=1e-12)


@pytest.mark.parametrize("project", [False, True], ids=["exact", "projected"])
def test_the_cached_fibre_products_are_the_direct_ones(model, project):
    """The conjugate gradients' products from the per-triangle caches against the
    products computed from the positions: muscle fibres with and without the force-length
    relation (some triangles below MIN_STRETCH, a schedule row at zero tension), passive
    fibres stretched and slack; to 1e-12 of the largest entry."""
    from hybrid import PassiveFibres
    from hybrid.terms.tangents import (
        passive_fibres_cached_product,
        passive_fibres_tangent_cache,
        passive_fibres_tangent_product,
    )

    a = model.arrays
    x = deformed(model, 12)
    for f in range(0, a.fib_vert.shape[0], 7):  # a few triangles shrunk below MIN_STRETCH
        tri = a.fib_vert[f]
        x[tri] = x[tri].mean(axis=0) + 0.02 * (x[tri] - x[tri].mean(axis=0))
    rng = np.random.default_rng(13)
    u = rng.standard_normal(x.shape)
    sv = sched(model)
    kx = 3e-5
    for width, tension in ((0.0, TENSION), (0.5, TENSION), (0.5, 0.0)):
        par = a.fib_par.copy()
        par[:, 4] = width
        sv[:, 0] = tension
        cache = np.zeros((a.fib_vert.shape[0], NFIB_CACHE))
        fibre_tangent_cache(a.fib_vert, par, a.fib_sched, sv, x, cache)
        want, got = np.zeros_like(u), np.zeros_like(u)
        fibre_tangent_product(a.fib_vert, par, a.fib_sched, sv, x, project, kx, u, want)
        fibre_cached_product(a.fib_vert, cache, project, kx, u, got)
        if tension == 0.0:
            assert np.abs(want).max() == 0.0 and np.abs(got).max() == 0.0
        else:
            assert np.abs(want).max() > 0.0
            assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()
    mesh = irregular_sphere(40, R, seed=2)
    p = compile_scene(
        Scene(
            mesh=mesh,
            masses=Masses(total_kg=1.0),
            integrator="implicit_euler",
            forces=(Membrane(800.0), PassiveFibres(modulus_n_per_m=600.0, around_axis=(0.0, 0.0, 1.0))),
        )
    ).arrays
    x = deformed(model, 14)
    cache = np.zeros((p.pf_vert.shape[0], NPF_CACHE))
    passive_fibres_tangent_cache(p.pf_vert, p.pf_par, x, cache)
    slack = int((cache[:, 9] == 0.0).sum())
    assert 0 < slack < p.pf_vert.shape[0]
    want, got = np.zeros_like(u), np.zeros_like(u)
    passive_fibres_tangent_product(p.pf_vert, p.pf_par, x, project, kx, u, want)
    passive_fibres_cached_product(p.pf_vert, cache, project, kx, u, got)
    assert np.abs(want).max() > 0.0
    assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()


def test_the_newton_rows_skip_only_triangles_of_fixed_points():
    """With the points below z = 0.04 m not integrated (as points linked to a rigid body: their
    triangles kept), the Newton matrix's product from `newton_rows` (the triangles with a free
    corner) is the product from every triangle on the free points."""
    from hybrid import PassiveFibres

    mesh = irregular_sphere(40, R, seed=2)
    a = compile_scene(
        Scene(
            mesh=mesh,
            masses=Masses(total_kg=1.0),
            integrator="implicit_euler",
            forces=(
                Membrane(800.0, damping_time_s=0.02),
                PassiveFibres(modulus_n_per_m=600.0, around_axis=(0.0, 0.0, 1.0)),
                MuscleFibres(HalfSpace((0.0, 0.0, -0.03), (0.0, 0.0, 1.0)), TENSION, toward_m=(0.0, 0.0, R)),
                RestingTension(tension_n_per_m=25.0),
                Damping(drag_n_s_per_m3=30.0),
            ),
        )
    ).arrays
    a = a._replace(vert_free=(a.vert_rest[:, 2] >= 0.04).astype(np.uint8))
    rows = newton_rows(a)
    free = a.vert_free != 0
    assert 0 < free.sum() < free.size
    names = ("mem_vert", "fib_vert", "pf_vert", "rt_vert")
    kept = [getattr(rows, name).shape[0] for name in names]
    every = [getattr(a, name).shape[0] for name in names]
    assert min(kept) > 0 and all(k < e for k, e in zip(kept, every)), (kept, every)
    x = a.vert_rest + 0.01 * np.random.default_rng(15).standard_normal(a.vert_rest.shape)
    u = np.random.default_rng(16).standard_normal(x.shape)
    sv = np.full((a.sched.kind.shape[0], 3), TENSION)
    out = []
    for r in (every_row(a), rows):
        face = np.zeros((r.mem_vert.shape[0], NCACHE))
        fib = np.zeros((r.fib_vert.shape[0], NFIB_CACHE))
        pf = np.zeros((r.pf_vert.shape[0], NPF_CACHE))
        newton_caches(a, r, sv, x, face, fib, pf)
        y = np.zeros_like(u)
        newton_product(a, r, face, fib, pf, 2e-3, False, u, y, no_planes(a))
        out.append(y[free])
    assert np.abs(out[0]).max() > 0.0
    assert np.abs(out[1] - out[0]).max() <= 1e-12 * np.abs(out[0]).max()
