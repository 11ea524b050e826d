"""The integrators' registry (`hybrid.integrators`) is the one list: the scene's choices,
the ids the compiled step reads, and which ones carry a solver's work arrays."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import hybrid
from hybrid.errors import SceneError
from hybrid.integrators import BY_NAME, INTEGRATORS, NAMES, is_implicit
from hybrid.scene import INTEGRATORS as SCENE_CHOICES


def test_the_scene_offers_exactly_the_registered_integrators():
    assert SCENE_CHOICES == NAMES == tuple(BY_NAME)
    assert [i.id for i in INTEGRATORS] == list(range(len(INTEGRATORS)))
    assert not is_implicit("no_such_integrator")


@pytest.mark.parametrize("integrator", NAMES)
def test_each_integrator_compiles_to_its_id_and_only_an_implicit_one_fills_solver_arrays(integrator):
    scene = hybrid.load_scene("breathing", overrides=["mesh.level=0", "dt_s=0.0005"])
    sim = hybrid.load(dataclasses.replace(scene, integrator=integrator))
    assert sim.model.arrays.integrator == BY_NAME[integrator].id
    assert (sim.solver_work.dv.size > 0) == is_implicit(integrator)  # the others' empty, of the same types
    sim.step(5)  # each steps through `hybrid.step.integrate`
    assert np.all(np.isfinite(sim.vert_pos)) and sim.steps_done == 5
    assert not np.array_equal(sim.vert_pos, sim.model.mesh.vert_pos)  # it moved


def test_an_integrator_that_needs_a_hessian_is_refused_for_the_paper_s_terms():
    scene = hybrid.load_scene("breathing_paper", overrides=["mesh.level=0"])
    needs = [i.name for i in INTEGRATORS if i.needs_hessian]
    assert needs == ["implicit_euler"]
    for name in needs:
        with pytest.raises(SceneError, match=f"integrator: '{name}' needs formulation 'continuum'"):
            hybrid.load(dataclasses.replace(scene, integrator=name))
