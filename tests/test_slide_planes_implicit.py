"""The sliding links' planes in implicit Euler's Newton solve (hybrid.terms.slide_planes): the
Newton matrix with a plane against central finite differences of the implicit forces, its
assembled blocks (and the preconditioner's diagonal) against the element products, and the
line search's potential against the forces, on a small irregular mesh with a point of a plane
that is not integrated (no row)."""

import numpy as np
import pytest
from helpers import central_differences, dense_matrix, every_row, no_planes

from hybrid import Damping, Masses, Membrane, RestingTension, Scene
from hybrid.implicit import _merit, _trial, implicit_forces, implicit_work, newton_caches, newton_product
from hybrid.implicit_matrix import assemble, newton_matrix
from hybrid.integrators import IMPLICIT_EULER_ID
from hybrid.mesh import irregular_sphere
from hybrid.model import compile_scene
from hybrid.terms.slide_planes import add_plane_forces, plane_energy, slide_planes
from hybrid.terms.tangents import NCACHE, NFIB_CACHE, NPF_CACHE

R = 0.12
H = 2e-3
# N/m: h^2 k = 4e-2 kg against a point's 2.5e-2 kg, so the plane's block is a large part of its row
K_N_PER_M = 1e4
SLIDING = np.array([3, 7, 11, 19, 23, 31], np.int32)


@pytest.fixture(scope="module")
def setup():
    a = compile_scene(
        Scene(
            mesh=irregular_sphere(40, R, seed=5),
            masses=Masses(total_kg=1.0),
            integrator="implicit_euler",
            forces=(
                Membrane(800.0, damping_time_s=0.02),
                RestingTension(tension_n_per_m=25.0),
                Damping(drag_n_s_per_m3=30.0),
            ),
        )
    ).arrays
    free = np.ones(a.vert_rest.shape[0], np.uint8)
    free[[0, 19]] = 0  # sliding point 19 is not integrated: its plane adds no block
    free.flags.writeable = False  # as a model's: the solve's own compiled kernels then serve these calls
    a = a._replace(vert_free=free, integrator=IMPLICIT_EULER_ID)
    rng = np.random.default_rng(11)
    k = K_N_PER_M * rng.uniform(0.5, 2.0, SLIDING.size)
    planes = slide_planes(a.vert_free, SLIDING, k)
    normal = rng.standard_normal((SLIDING.size, 3))
    planes.normal[:] = normal / np.linalg.norm(normal, axis=1)[:, None]
    planes.origin[:] = a.vert_rest[SLIDING] + 0.01 * rng.standard_normal((SLIDING.size, 3))
    assert list(planes.row[SLIDING == 19]) == [-1]
    x = a.vert_rest + 0.01 * rng.standard_normal(a.vert_rest.shape)
    return a, planes, x


def rel_error(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


def caches(a, x):
    face = np.zeros((a.mem_vert.shape[0], NCACHE))
    fib, pf = np.zeros((0, NFIB_CACHE)), np.zeros((0, NPF_CACHE))
    newton_caches(a, every_row(a), np.zeros((a.sched.kind.shape[0], 3)), x, face, fib, pf)
    return face, fib, pf


def test_the_newton_matrix_with_a_plane_against_finite_differences_of_the_implicit_forces(setup):
    """M + h^2 K + h C, the planes' h^2 k n n^T on their points' diagonal blocks included,
    against M - h^2 dF/dx - h dF/dv of the implicit forces with the planes (dF/dx at v = 0,
    as tests/terms/test_tangents.py)."""
    a, planes, x = setup
    n = x.shape[0]
    sv = np.zeros((a.sched.kind.shape[0], 3))
    face, fib, pf = caches(a, x)
    work = implicit_work(a)
    zero = np.zeros_like(x)
    v = 0.05 * np.random.default_rng(2).standard_normal(x.shape)

    def forces(y, w, with_planes=True):
        f = np.zeros_like(y)
        if with_planes:
            implicit_forces(a, every_row(a), sv, y, w, f, work, planes)
        else:
            implicit_forces(a, every_row(a), sv, y, w, f, work, no_planes(a))
        return f

    newton = dense_matrix(n, lambda u, y: newton_product(a, every_row(a), face, fib, pf, H, False, u, y, planes))
    without = dense_matrix(n, lambda u, y: newton_product(a, every_row(a), face, fib, pf, H, False, u, y, no_planes(a)))
    mass = np.diag(np.repeat(a.vert_mass, 3))
    expected = mass - H * H * central_differences(lambda y: forces(y, zero), x, 1e-7)
    expected -= H * central_differences(lambda w: forces(x, w), v, 1e-4)
    assert rel_error(newton - mass, expected - mass) <= 1e-6
    # the planes' part is there, and is h^2 k n n^T on their points' diagonal blocks alone
    plane = np.zeros_like(newton)
    for j, i in enumerate(planes.vert):
        plane[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = (
            H * H * planes.stiffness[j] * np.outer(planes.normal[j], planes.normal[j])
        )
    assert np.abs(newton - without - plane).max() <= 1e-12 * np.abs(newton).max()
    assert np.abs(plane).max() > 0.5 * a.vert_mass.max()
    # the forces: the implicit ones plus -k g n
    f_planes = np.zeros_like(x)
    add_plane_forces(planes, x, f_planes)
    np.testing.assert_allclose(
        forces(x, v) - forces(x, v, False), f_planes, rtol=0, atol=1e-12 * np.abs(f_planes).max()
    )


def test_the_assembled_matrix_and_its_preconditioner_hold_the_planes(setup):
    a, planes, x = setup
    n = x.shape[0]
    face, fib, pf = caches(a, x)
    empty = np.zeros((0, 3), np.int32)
    mat = newton_matrix(n, a.vert_free, a.mem_vert, empty, empty, a.rt_vert)
    bare = newton_matrix(n, a.vert_free, a.mem_vert, empty, empty, a.rt_vert)
    assemble(a, every_row(a), face, fib, pf, H, mat, planes)
    assemble(a, every_row(a), face, fib, pf, H, bare, no_planes(a))
    row_of = {int(i): f for f, i in enumerate(mat.free)}
    diag = mat.row_ptr[:-1]
    for j, i in enumerate(planes.vert):
        block = (H * H * planes.stiffness[j] * np.outer(planes.normal[j], planes.normal[j])).ravel()
        if i not in row_of:
            continue
        f = row_of[int(i)]
        np.testing.assert_allclose(mat.amat[diag[f]] - bare.amat[diag[f]], block, rtol=0, atol=1e-15)
        # positive semi-definite: the preconditioner's projected diagonal takes it as it is
        np.testing.assert_allclose(mat.pdiag[i] - bare.pdiag[i], block, rtol=0, atol=1e-15)
    others = np.setdiff1d(np.arange(mat.amat.shape[0]), diag[[row_of[int(i)] for i in planes.vert if int(i) in row_of]])
    assert np.array_equal(mat.amat[others], bare.amat[others])


def test_the_potential_changes_by_the_planes_energy_whose_gradient_is_minus_their_force(setup):
    a, planes, x = setup
    f = np.zeros_like(x)
    add_plane_forces(planes, x, f)
    grad = np.zeros(x.size)
    for j in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp.flat[j] += 1e-6
        xm.flat[j] -= 1e-6
        grad[j] = (plane_energy(planes, xp) - plane_energy(planes, xm)) / 2e-6
    assert rel_error(-grad.reshape(x.shape), f) <= 1e-6
    assert np.abs(f[np.setdiff1d(np.arange(x.shape[0]), planes.vert)]).max() == 0.0
    # the line search's potential: the planes' energy at x_try added to the rest
    with_planes = implicit_work(a)._replace(planes=planes)
    without = implicit_work(a)
    sv = np.zeros((a.sched.kind.shape[0], 3))
    dv = 0.01 * np.random.default_rng(4).standard_normal(x.shape)
    vel = np.zeros_like(x)
    parts = []
    for w in (with_planes, without):
        _trial(a, x, vel, H, dv, w)
        w.x_kv[:] = w.x_try
        parts.append(_merit(a, sv, H, dv, w))
    assert parts[0] - parts[1] == pytest.approx(plane_energy(planes, with_planes.x_try), rel=1e-12)
    assert plane_energy(planes, with_planes.x_try) > 1e-3 * abs(parts[1])
