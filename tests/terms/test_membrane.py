"""The continuum formulation's elastic membrane (hybrid.terms.membrane): minus the
gradient of its energy, free of net force and moment, exact on the patch test,
the same in both builds, and dissipative only in relative motion."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

import hybrid
from hybrid import Masses, Membrane, MeshSpec, Scene, Volume
from hybrid.errors import SceneError
from hybrid.mesh import Mesh, icosphere, irregular_sphere, uv_sphere
from hybrid.readouts import net_internal, swept_volume
from hybrid.terms.membrane import (
    add_membrane_serial,
    lame_moduli,
    membrane_energy,
    membrane_faces_parallel,
    membrane_gather_parallel,
)

FAMILIES = {
    "uv": lambda: uv_sphere(0.12, 16, 9),
    "ico": lambda: icosphere(2, 0.12),
    "irregular": lambda: irregular_sphere(300, 0.12, seed=3),
}


def model_of(mesh, **kw):
    return hybrid.compile_scene(
        Scene(mesh=mesh, masses=Masses(total_kg=1.0), forces=(Membrane(kw.pop("youngs", 800.0), **kw),))
    )


def forces(a, x, v=None):
    f = np.zeros_like(x)
    add_membrane_serial(a.mem_vert, a.mem_par, a.kv_on, x, np.zeros_like(x) if v is None else v, f)
    return f


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("nu", [0.0, 0.3, 0.5])
def test_the_force_is_minus_the_energy_gradient(family, nu):
    a = model_of(FAMILIES[family](), poisson_ratio=nu).arrays
    x = a.vert_rest + 0.01 * np.random.default_rng(1).standard_normal(a.vert_rest.shape)  # 10% strains
    f = forces(a, x)
    # central differences: truncation h^2 E''' ~ 1e-14 relative, round-off eps E / h ~ 1e-9 of |F|
    h = 1e-6
    fd = np.zeros((12, 3))
    for n, i in enumerate(range(0, a.vert_rest.shape[0], a.vert_rest.shape[0] // 12)[:12]):
        for c in range(3):
            y = x.copy()
            y[i, c] += h
            ep = membrane_energy(a.mem_vert, a.mem_par, y)
            y[i, c] -= 2 * h
            fd[n, c] = -(ep - membrane_energy(a.mem_vert, a.mem_par, y)) / (2 * h)
    rows = list(range(0, a.vert_rest.shape[0], a.vert_rest.shape[0] // 12))[:12]
    assert np.abs(fd - f[rows]).max() <= 1e-6 * np.abs(f).max()


@pytest.mark.parametrize("family", FAMILIES)
def test_net_force_and_moment_vanish_at_any_shape(family):
    a = model_of(FAMILIES[family]()).arrays
    x = a.vert_rest * 1.1 + 0.02 * np.random.default_rng(2).standard_normal(a.vert_rest.shape) + 3.0
    net = net_internal(x, forces(a, x))
    # each triangle's three forces sum to zero and their moment to zero: round-off of the sums only
    assert np.abs(net["net_force_n"]).max() <= 1e-13 * net["sum_abs_force_n"]
    assert np.abs(net["net_moment_n_m"]).max() <= 1e-13 * net["sum_abs_moment_n_m"]


def test_rest_and_rigid_motions_cost_nothing():
    a = model_of(FAMILIES["irregular"]()).arrays
    rot = np.linalg.qr(np.random.default_rng(4).standard_normal((3, 3)))[0]
    rot *= np.sign(np.linalg.det(rot))
    for x in (a.vert_rest, a.vert_rest @ rot.T + (1.0, -2.0, 0.5)):
        assert membrane_energy(a.mem_vert, a.mem_par, x) <= 1e-25
        assert np.abs(forces(a, x)).max() <= 1e-12 * 800.0 * 0.12


def flat_patch(n=9, seed=0):
    """An irregular triangulation of the unit square (m) in the z = 0 plane."""
    g = np.linspace(0.0, 1.0, n)
    p = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    inner = (p > 0).all(1) & (p < 1).all(1)
    p[inner] += np.random.default_rng(seed).uniform(-0.3, 0.3, (inner.sum(), 2)) / (n - 1)
    tri = Delaunay(p).simplices
    return Mesh.from_arrays(np.c_[p, np.zeros(len(p))], tri), inner


@pytest.mark.parametrize("nu", [0.0, 0.3])
def test_the_patch_test_holds_exactly(nu):
    """A uniform in-plane stretch of an irregular patch: every interior point is in
    equilibrium, and the boundary forces carry the closed-form stress of the law."""
    mesh, inner = flat_patch()
    a = model_of(mesh, youngs=1000.0, poisson_ratio=nu).arrays
    F = np.array([[1.05, 0.02, 0.0], [0.01, 0.97, 0.0], [0.0, 0.0, 1.0]])
    x = a.vert_rest @ F.T
    f = forces(a, x)
    scale = 1000.0 * 0.05 / 8  # Y x strain x edge length: a typical point force (N)
    assert np.abs(f[inner]).max() <= 1e-12 * scale
    # the boundary forces' virtual work in a uniform displacement gradient G is -A P:G
    # (P = F S the first Piola stress of the closed-form law, A = 1 m^2): exact on any mesh
    lam, mu = lame_moduli(1000.0, nu)
    F2 = F[:2, :2]
    E = 0.5 * (F2.T @ F2 - np.eye(2))
    P = F2 @ (lam * np.trace(E) * np.eye(2) + 2 * mu * E)
    work = f[:, :2].T @ a.vert_rest[:, :2]  # sum_i f_i,r X_i,c
    assert np.allclose(work, -P, rtol=0, atol=1e-12 * np.abs(P).max())


def test_serial_and_parallel_builds_agree_to_the_bit():
    a = model_of(FAMILIES["irregular"](), damping_time_s=0.01).arrays
    rng = np.random.default_rng(5)
    x = a.vert_rest + 0.005 * rng.standard_normal(a.vert_rest.shape)
    v = rng.standard_normal(x.shape)
    f1, f2 = np.ones_like(x), np.ones_like(x)  # both builds add to the forces already there
    add_membrane_serial(a.mem_vert, a.mem_par, a.kv_on, x, v, f1)
    ff = np.zeros((len(a.mem_vert), 6))
    membrane_faces_parallel(a.mem_vert, a.mem_par, a.kv_on, x, v, ff)
    membrane_gather_parallel(a.mvf_ptr, a.mvf_slot, ff, f2)
    assert np.array_equal(f1, f2)


def test_kelvin_voigt_viscosity_only_dissipates_and_ignores_rigid_motion():
    mesh = FAMILIES["ico"]()
    a = model_of(mesh, damping_time_s=0.02).arrays
    x = a.vert_rest * 1.02
    elastic = forces(model_of(mesh).arrays, x)
    rng = np.random.default_rng(6)
    w = rng.standard_normal(3)
    rigid_v = np.cross(w, x) + rng.standard_normal(3)
    assert np.abs(forces(a, x, rigid_v) - elastic).max() <= 1e-12 * np.abs(elastic).max()
    for _ in range(5):
        v = rng.standard_normal(x.shape)
        viscous = forces(a, x, v) - elastic
        assert np.einsum("ij,ij->", viscous, v) < 0  # power of the viscous forces


def test_swept_volumes_of_a_partition_add_up_to_the_volume_change():
    mesh = FAMILIES["irregular"]()
    x = mesh.vert_pos * (1 + 0.1 * np.random.default_rng(7).random((mesh.nvert, 1)))
    top = np.nonzero(mesh.vert_pos[:, 2] > 0.03)[0]
    rest = np.setdiff1d(np.arange(mesh.nvert), top)
    from hybrid.readouts import region_faces

    parts = [
        swept_volume(mesh.face_vert[region_faces(mesh.face_vert, r, mesh.nvert)], mesh.vert_pos, x) for r in (top, rest)
    ]
    dv = Mesh.from_arrays(x, mesh.face_vert).volume() - mesh.volume()
    assert abs(sum(parts) - dv) <= 1e-14 * mesh.volume() * 10
    assert parts[0] > 0 and parts[1] > 0


def _swept_reference(face_vert, rest, pos):
    """The swept volume by its formula in numpy, face by face (the slow reference)."""
    X, x = rest[face_vert], pos[face_vert]
    d = x - X
    E1, E2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    d1, d2 = d[:, 1] - d[:, 0], d[:, 2] - d[:, 0]
    n = 0.5 * (np.cross(E1, E2) + 0.5 * (np.cross(E1, d2) + np.cross(d1, E2)) + np.cross(d1, d2) / 3.0)
    return float(np.einsum("ij,ij->", d.mean(axis=1), n))


def test_compiled_swept_volumes_of_frames_match_the_formula_and_a_prism():
    from hybrid.readouts import swept_volumes

    mesh = FAMILIES["irregular"]()
    rng = np.random.default_rng(8)
    frames = mesh.vert_pos + 0.05 * rng.standard_normal((4, mesh.nvert, 3))
    faces = mesh.face_vert[mesh.vert_pos[mesh.face_vert].mean(axis=1)[:, 2] > 0.0]
    got = swept_volumes(faces, mesh.vert_pos, frames)
    want = np.array([_swept_reference(faces, mesh.vert_pos, p) for p in frames])
    # the same sums in another order: rounding only (1e-12 of the sum of absolute terms' scale)
    assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()
    # a right triangle of legs 0.3 and 0.2 moved 0.05 along its normal sweeps a prism: A h
    tri = np.array([[0, 1, 2]])
    rest = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.2, 0.0]])
    moved = rest + [0.01, -0.02, 0.05]
    assert swept_volumes(tri, rest, moved[None])[0] == pytest.approx(0.5 * 0.3 * 0.2 * 0.05, rel=1e-14)


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("youngs_modulus_n_per_m", -1.0, r"youngs_modulus_n_per_m: expected a number > 0"),
        ("poisson_ratio", 0.6, r"poisson_ratio: expected a number in \[0, 0.5\], received 0.6"),
        ("damping_time_s", -0.1, r"damping_time_s: expected a number >= 0"),
    ],
)
def test_bad_membrane_values_are_one_line(field, value, message):
    kw = {"youngs_modulus_n_per_m": 100.0, field: value}
    scene = Scene(
        mesh=MeshSpec(generator="icosphere", subdivisions=1),
        masses=Masses(total_kg=1.0),
        forces=(Membrane(**kw),),
        constraints=(Volume(),),
    )
    with pytest.raises(SceneError, match=message) as e:
        hybrid.compile_scene(scene)
    assert "\n" not in str(e.value)
