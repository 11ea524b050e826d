"""Passive fibres (hybrid.terms.passive_fibres): the force is minus the energy's gradient,
has no net force or moment, is slack in compression, and the modulus means the same on
every mesh: a uniform dilation stores E_f / 2 e^2 per unit rest area on three families."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import forces_at

from hybrid.errors import SceneError
from hybrid.mesh import fibonacci_sphere, ring_sphere, uv_sphere
from hybrid.model import compile_scene
from hybrid.scene import Masses, PassiveFibres, Scene
from hybrid.terms.passive_fibres import passive_fibres_energy

R = 0.1
MESHES = {"uv_sphere": uv_sphere(R, 26, 13), "ring_sphere": ring_sphere(600, R), "fibonacci": fibonacci_sphere(600, R)}
E_F = 500.0  # N/m


def _model(mesh, **direction):
    return compile_scene(
        Scene(
            mesh=mesh,
            masses=Masses(total_kg=1.0),
            forces=(PassiveFibres(modulus_n_per_m=E_F, **(direction or {"around_axis": (0.0, 0.0, 1.0)})),),
        )
    )


def _forces(model, pos):
    return forces_at(model, pos)[0]


def _area(mesh):
    p = mesh.vert_pos[mesh.face_vert]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()


@pytest.mark.parametrize("family", MESHES)
def test_a_dilation_stores_the_same_energy_per_area_on_every_mesh(family):
    mesh = MESHES[family]
    a = _model(mesh).arrays
    stretch = 1.03
    e = (stretch**2 - 1) / 2  # the Green strain of a uniform dilation, along any direction
    # exact on any triangulation: the fibre strain of a linear triangle is f . E f exactly
    energy = passive_fibres_energy(a.pf_vert, a.pf_par, mesh.vert_pos * stretch)
    assert energy == pytest.approx(0.5 * E_F * e * e * _area(mesh), rel=1e-12)
    # compression: the fibres are slack
    assert passive_fibres_energy(a.pf_vert, a.pf_par, mesh.vert_pos * 0.97) == 0.0
    assert np.abs(_forces(_model(mesh), mesh.vert_pos * 0.97)).max() == 0.0


@pytest.mark.parametrize("family", MESHES)
def test_the_force_is_minus_the_energy_gradient_without_net_force_or_moment(family):
    mesh = MESHES[family]
    model = _model(mesh)
    a = model.arrays
    rng = np.random.default_rng(3)
    pos = mesh.vert_pos * 1.02 + rng.normal(scale=1e-3, size=mesh.vert_pos.shape)
    force = _forces(model, pos)
    arm = pos - pos.mean(axis=0)
    assert np.linalg.norm(force.sum(axis=0)) <= 1e-12 * np.linalg.norm(force, axis=1).sum()
    assert (
        np.linalg.norm(np.cross(arm, force).sum(axis=0)) <= 1e-12 * np.linalg.norm(np.cross(arm, force), axis=1).sum()
    )
    # central differences: error O(h^2) of the energy's third derivative, h = 1e-7 m
    h = 1e-7
    for i in rng.choice(mesh.nvert, 5, replace=False):
        for x in range(3):
            up, dn = pos.copy(), pos.copy()
            up[i, x] += h
            dn[i, x] -= h
            grad = (passive_fibres_energy(a.pf_vert, a.pf_par, up) - passive_fibres_energy(a.pf_vert, a.pf_par, dn)) / (
                2 * h
            )
            assert -grad == pytest.approx(force[i, x], rel=1e-5, abs=1e-9 * np.abs(force).max())


def test_hoops_resist_a_bulge_and_not_a_stretch_along_the_axis():
    mesh = MESHES["ring_sphere"]
    a = _model(mesh).arrays
    bulge = mesh.vert_pos * np.array([1.02, 1.02, 1.0])  # radial: stretches the hoops
    along = mesh.vert_pos * np.array([1.0, 1.0, 1.02])  # axial: the hoops keep their length
    e_bulge = passive_fibres_energy(a.pf_vert, a.pf_par, bulge)
    assert e_bulge > 0
    assert passive_fibres_energy(a.pf_vert, a.pf_par, along) < 1e-6 * e_bulge


def test_one_direction_is_required():
    mesh = MESHES["uv_sphere"]
    with pytest.raises(SceneError, match="expected exactly one fibre direction.*received none"):
        compile_scene(Scene(mesh=mesh, forces=(PassiveFibres(modulus_n_per_m=E_F),)))
    with pytest.raises(SceneError, match="around_axis: expected a non-zero vector"):
        _model(mesh, around_axis=(0.0, 0.0, 0.0))
    with pytest.raises(SceneError, match="passive_fibres.*formulation"):
        compile_scene(
            Scene(mesh=mesh, formulation="paper", forces=(PassiveFibres(modulus_n_per_m=E_F, around_axis=(0, 0, 1)),))
        )
