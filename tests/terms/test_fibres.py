"""Muscle fibres that pull both ends (hybrid.terms.fibres; issue 11, item 3): no net
force or moment at any resolution, minus the gradient of the fibres' work function,
and a fibre geometry that carries the same tension per unit width on every mesh."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import forces_at

from hybrid.errors import SceneError
from hybrid.mesh import Mesh, icosphere, uv_sphere
from hybrid.model import compile_scene
from hybrid.regions import Ball, HalfSpace
from hybrid.scene import Masses, MuscleFibres, Scene
from hybrid.schedule import Breathing, evaluate
from hybrid.terms.fibres import add_muscle_fibres, fibre_shares
from hybrid.terms.tangents import fibre_energy

R = 0.1
LEVELS = {
    "icosphere": [icosphere(k, R) for k in (1, 2, 3)],
    "uv_sphere": [uv_sphere(R, s, s // 2) for s in (13, 26, 52)],
}
DOME = HalfSpace((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))  # the upper half, fibres along its meridians


def _model(mesh, tension=40.0):
    return compile_scene(
        Scene(mesh=mesh, masses=Masses(total_kg=1.0), forces=(MuscleFibres(DOME, tension, toward_m=(0.0, 0.0, R)),))
    )


def _forces(model, pos, t=0.0):
    return forces_at(model, pos, t)[0]


@pytest.mark.parametrize("family", LEVELS)
def test_no_net_force_or_moment_at_any_resolution(family):
    rng = np.random.default_rng(11)
    for mesh in LEVELS[family]:
        model = _model(mesh)
        pos = mesh.vert_pos + rng.normal(scale=2e-3, size=mesh.vert_pos.shape)
        force = _forces(model, pos)
        arm = pos - pos.mean(axis=0)
        moment = np.cross(arm, force)
        assert np.abs(force).sum() > 1.0  # it pulls
        assert np.linalg.norm(force.sum(axis=0)) <= 1e-12 * np.linalg.norm(force, axis=1).sum(), mesh.nvert
        assert np.linalg.norm(moment.sum(axis=0)) <= 1e-12 * np.linalg.norm(moment, axis=1).sum(), mesh.nvert


@pytest.mark.parametrize("width", [0.0, 0.5], ids=["no_force_length", "force_length"])
def test_the_force_is_minus_the_gradient_of_the_fibres_work_function(width):
    """E = sum over triangles A T Psi(lambda) (Psi' the force-length relation), by central
    differences at strains of about 10%, at a time a breathing schedule gives T(t) = 30 N/m
    x its waveform."""
    mesh = LEVELS["uv_sphere"][1]
    model = compile_scene(
        Scene(
            mesh=mesh,
            masses=Masses(total_kg=1.0),
            forces=(MuscleFibres(DOME, Breathing(4.0, 0.4, 30.0), toward_m=(0.0, 0.0, R), force_length_width=width),),
        )
    )
    a = model.arrays
    rng = np.random.default_rng(5)
    pos = mesh.vert_pos + rng.normal(scale=1e-2 * R, size=mesh.vert_pos.shape)
    t = 0.8
    force = _forces(model, pos, t)
    sv = np.zeros((a.sched.kind.shape[0], 3))
    sv[:, 0] = float(np.asarray(evaluate(Breathing(4.0, 0.4, 30.0), t)).reshape(-1)[0])
    assert sv[0, 0] > 1.0

    def energy(x):
        return fibre_energy(a.fib_vert, a.fib_par, a.fib_sched, sv, x)

    eps = 1e-7 * R
    for i in rng.choice(np.unique(a.fib_vert), 12, replace=False):
        for c in range(3):
            plus, minus = pos.copy(), pos.copy()
            plus[i, c] += eps
            minus[i, c] -= eps
            fd = -(energy(plus) - energy(minus)) / (2 * eps)
            assert fd == pytest.approx(force[i, c], abs=1e-6 * np.abs(force).max())


def test_a_shortened_fibre_pulls_by_the_force_length_relation():
    """A flat sheet with fibres along x, squeezed uniformly along them to stretch 0.8:
    the force across a cut is T exp(-((0.8 - 1) / w)^2) per unit rest width (none across
    the fibres), on a regular and a perturbed triangulation."""
    rng = np.random.default_rng(4)
    w, stretch = 0.5, 0.8
    for jitter in (0.0, 0.3):
        pos, face = _sheet(8, jitter, rng)
        model = compile_scene(
            Scene(
                mesh=Mesh.from_arrays(pos, face),
                masses=Masses(total_kg=1.0),
                forces=(MuscleFibres("all", 1.0, axis=(1.0, 0.0, 0.0), force_length_width=w),),
            )
        )
        squeezed = pos * [stretch, 1.0, 1.0]
        force = _forces(model, squeezed)
        left = pos[:, 0] < 0.37
        # the force on the left part from the triangles across the cut: its net, as the sheet is free
        inside = np.zeros_like(force)
        a = model.arrays
        keep = left[a.fib_vert].all(axis=1)
        add_muscle_fibres(a.fib_vert[keep], a.fib_par[keep], a.fib_sched[keep], np.ones((1, 3)), squeezed, inside)
        across = (force - inside)[left].sum(axis=0)
        np.testing.assert_allclose(across, [np.exp(-(((stretch - 1) / w) ** 2)), 0.0, 0.0], rtol=0, atol=1e-12)


def _cut_force(pos, edge, share, left):
    """The fibre force (per unit T) on the points `left` from the edges that cross to the rest."""
    a, b = edge[:, 0], edge[:, 1]
    cross = left[a] != left[b]
    i, j = np.where(left[a], a, b)[cross], np.where(left[a], b, a)[cross]
    d = pos[j] - pos[i]
    return (share[cross, None] * d / np.linalg.norm(d, axis=1)[:, None]).sum(axis=0)


def _sheet(n, jitter, rng):
    """The unit square in n x n cells of two triangles, inner points moved by up to jitter cells."""
    x = np.linspace(0.0, 1.0, n + 1)
    gx, gy = np.meshgrid(x, x, indexing="ij")
    pos = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    inner = (pos[:, 0] > 0) & (pos[:, 0] < 1) & (pos[:, 1] > 0) & (pos[:, 1] < 1)
    pos[inner, :2] += rng.uniform(-jitter, jitter, (inner.sum(), 2)) / n
    k = np.arange(n * (n + 1)).reshape(n, n + 1)[:, :n].ravel()  # lower-left corner of each cell
    a, b, c, d = k, k + n + 1, k + n + 2, k + 1
    return pos, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


@pytest.mark.parametrize("jitter", [0.0, 0.3], ids=["regular", "perturbed"])
def test_a_flat_sheet_carries_the_tension_times_the_width_across_any_cut(jitter):
    """Uniform fibres along x in a unit square sheet: the force across a cut x = const
    is T x 1 m along x, at every resolution, on a regular and a randomly perturbed
    triangulation (a uniform stress is carried exactly: the patch test)."""
    rng = np.random.default_rng(2)
    for n in (4, 9, 20):
        pos, face = _sheet(n, jitter, rng)
        edge, share = fibre_shares(pos, face, axis=(1.0, 0.0, 0.0))
        for x_cut in (0.37, 0.61):
            np.testing.assert_allclose(
                _cut_force(pos, edge, share, pos[:, 0] < x_cut), [1.0, 0.0, 0.0], rtol=0, atol=1e-12
            )


def test_meridian_fibres_carry_t_times_the_equator_across_it_on_both_families():
    """Fibres along the meridians of a sphere (toward the north pole), T = 1 N/m: the pull
    of the southern fibres on the northern half is 2 pi R T along -z. Measured relative
    errors 2.4 / 0.60 / 0.15 % (icospheres 162 / 642 / 2562 points) and 6.6 / 1.7 /
    0.43 % (UV spheres 114 / 482 / 1986): second order toward the same value."""
    errs = {}
    for family, meshes in (
        ("icosphere", [icosphere(k, R) for k in (2, 3, 4)]),
        ("uv_sphere", [uv_sphere(R, s, s // 2) for s in (16, 32, 64)]),
    ):
        for mesh in meshes:
            edge, share = fibre_shares(mesh.vert_pos, mesh.face_vert, toward=(0.0, 0.0, R))
            f = _cut_force(mesh.vert_pos, edge, share, mesh.vert_pos[:, 2] > 1e-9 * R)
            assert np.abs(f[:2]).max() <= 1e-12
            errs.setdefault(family, []).append(abs(f[2] / (-2 * np.pi * R) - 1))
    for family, e in errs.items():
        assert e[-1] < 0.005, (family, e)
        assert all(3.5 < e[k] / e[k + 1] < 4.5 for k in range(2)), (family, e)  # order 2


def test_a_region_without_triangles_and_a_missing_direction_are_refused():
    mesh = LEVELS["icosphere"][0]
    far = Ball((0.0, 0.0, 0.0), 0.5 * R)  # inside the sphere, no point: refused by the region itself
    near_one = Ball(tuple(mesh.vert_pos[0]), 1e-3 * R)  # one point: no triangle
    for sel, pattern in (
        (near_one, r"forces\['muscle_fibres'\]\.region: expected triangles in the region"),
        (far, r"selects none"),
    ):
        with pytest.raises(SceneError, match=pattern):
            compile_scene(
                Scene(mesh=mesh, masses=Masses(total_kg=1.0), forces=(MuscleFibres(sel, 10.0, axis=(0.0, 0.0, 1.0)),))
            )
    with pytest.raises(SceneError, match=r"expected exactly one fibre direction, toward_m or axis"):
        compile_scene(Scene(mesh=mesh, masses=Masses(total_kg=1.0), forces=(MuscleFibres("all", 10.0),)))
    with pytest.raises(SceneError, match=r"type 'muscle_fibres' belongs to formulation 'continuum'"):
        compile_scene(
            Scene(
                formulation="paper",
                mesh=mesh,
                masses=Masses(total_kg=1.0),
                forces=(MuscleFibres("all", 10.0, axis=(0.0, 0.0, 1.0)),),
            )
        )
