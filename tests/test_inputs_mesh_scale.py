"""A body of the wrong size or in several pieces is refused at scene build, in one line,
before it can run and diverge; what the line suggests is accepted. (The command line's
one line and exit status: tests/data/bad_inputs/cases.toml, mesh_in_millimetres,
mesh_radius_in_millimetres, mesh_two_surfaces_one_volume.)"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import hybrid
from hybrid.errors import HybridError, SceneError
from hybrid.model import MAX_BODY_M, compile_scene
from hybrid.scenefile import load_scene

BAD = Path(__file__).parent / "data" / "bad_inputs" / "scenes"


def test_a_mesh_in_millimetres_is_refused_naming_its_size_and_the_scale_that_fits():
    sc = load_scene(BAD / "mesh_in_millimetres.toml")
    with pytest.raises(SceneError) as exc:
        compile_scene(sc)
    msg = str(exc.value)
    assert "\n" not in msg and "tetra_mm.obj" in msg and "a body 100 m across" in msg
    assert f"at most {MAX_BODY_M:g} m across" in msg and "mesh.unit_scale = 0.001" in msg
    # what it suggests: the same file read in millimetres, a 0.1 m tetrahedron
    m = compile_scene(dataclasses.replace(sc, mesh=dataclasses.replace(sc.mesh, unit_scale=0.001)))
    assert np.ptp(m.mesh.vert_pos, axis=0).max() == pytest.approx(0.1, rel=1e-12)


@pytest.mark.parametrize(("radius", "unit", "fix"), [(120.0, "millimetres", 0.12), (12.0, "centimetres", 0.12)])
def test_a_radius_in_millimetres_or_centimetres_is_refused(radius, unit, fix):
    sc = hybrid.Scene(mesh=hybrid.MeshSpec(radius_m=radius), forces=(hybrid.Membrane(youngs_modulus_n_per_m=100.0),))
    with pytest.raises(SceneError, match=rf"^mesh.radius_m: a body .* m across \(radius_m = {radius:g}\); .*{unit}"):
        compile_scene(sc)
    assert compile_scene(dataclasses.replace(sc, mesh=hybrid.MeshSpec(radius_m=fix))).nvert == 80
    # the largest body accepted: 10 m across (a radius of 5 m); a trunk is 0.3 m
    compile_scene(dataclasses.replace(sc, mesh=hybrid.MeshSpec(radius_m=MAX_BODY_M / 2)))


def test_a_mesh_given_as_an_object_is_checked_too():
    big = hybrid.mesh.icosphere(1, 150.0)
    with pytest.raises(SceneError, match=r"^mesh: the Mesh 'icosphere1' is a body 300 m across; .*by 0.001"):
        compile_scene(hybrid.Scene(mesh=big, forces=(hybrid.Membrane(youngs_modulus_n_per_m=100.0),)))


def test_two_disjoint_surfaces_under_one_volume_are_refused_naming_each():
    a, b = hybrid.mesh.icosphere(1, 0.1), hybrid.mesh.icosphere(2, 0.05)
    two = hybrid.mesh.Mesh.from_arrays(
        np.vstack([a.vert_pos, b.vert_pos + [0.3, 0.0, 0.0]]),
        np.vstack([a.face_vert, b.face_vert + a.nvert]),
        name="two",
    )
    assert [len(p) for p in two.components()] == [a.nvert, b.nvert]
    for term, what in (
        (hybrid.Volume(), "a constant-volume constraint"),
        (hybrid.SoftVolume(bulk_modulus_pa=1e4), "compressible volume"),
    ):
        forces = (hybrid.Membrane(youngs_modulus_n_per_m=100.0),)
        sc = hybrid.Scene(mesh=two, masses=hybrid.Masses(total_kg=1.0), forces=forces)
        sc = (
            dataclasses.replace(sc, constraints=(term,))
            if isinstance(term, hybrid.Volume)
            else (dataclasses.replace(sc, forces=forces + (term,)))
        )
        with pytest.raises(HybridError) as exc:
            compile_scene(sc)
        msg = str(exc.value)
        assert "\n" not in msg and what in msg and "'two' is 2 disjoint surfaces" in msg
        # each piece named: its points, where it is, its volume (the 42-point icosphere's 3.66 L)
        assert "42 points about (0, 0, 0) m enclosing 3.66 L" in msg and "162 points about (0.3, 0, 0) m" in msg
    # without a volume term the pieces are a membrane of two parts: accepted
    assert compile_scene(hybrid.Scene(mesh=two, forces=(hybrid.Membrane(youngs_modulus_n_per_m=100.0),))).nvert == 204
