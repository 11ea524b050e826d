"""The step's fused per-point force pass (hybrid.terms.pointwise): gravity, damping and the
shape memory in one pass over chunks of points, equal to the terms computed one by one."""

from __future__ import annotations

import numpy as np
import pytest

from hybrid.implicit_work import no_implicit_work
from hybrid.model import compile_scene
from hybrid.terms.shape_memory import add_shape_memory


@pytest.mark.parametrize("subdivisions, parallel", [(3, False), (4, True)])
def test_step_forces_are_the_terms_added_point_by_point(subdivisions, parallel):
    """The step sets gravity, damping and the shape memory in one pass over chunks
    of points, walking the shape-memory points from each chunk's first on; with
    a nailed cap (shape memory on a subset) and meshes of several chunks, its
    forces equal the terms computed one by one."""
    import dataclasses

    from hybrid.bench import bench_membrane
    from hybrid.step import membrane_forces
    from hybrid.step_work import new_control, new_state, new_work

    model = compile_scene(bench_membrane(subdivisions))
    model = dataclasses.replace(model, arrays=model.arrays._replace(parallel=parallel))
    a = model.arrays
    assert 0 < a.sm_vert.size < model.nvert  # a subset: the nailed cap has none
    rng = np.random.default_rng(3)
    state = new_state(a)
    state.vert_pos[:] = a.vert_rest + rng.normal(scale=1e-3, size=a.vert_rest.shape)
    state.vert_vel[:] = rng.normal(scale=1e-2, size=a.vert_rest.shape)
    work = new_work(a, state)
    membrane_forces(a, state, work, no_implicit_work(a), new_control(a), 0.0)
    want = np.where(a.vert_free[:, None] > 0, a.vert_mass[:, None] * a.accel[None, :], 0.0)
    want -= a.damp_coef[:, None] * state.vert_vel
    add_shape_memory(
        a.sm_vert,
        a.sm_stiff,
        a.sm_coef,
        a.ring_ptr,
        a.ring_vert,
        a.ring_closed,
        state.vert_pos,
        np.zeros((a.sm_vert.size, 9)),
        want,
    )
    np.testing.assert_allclose(work.vert_force, want, rtol=0, atol=1e-13 * np.abs(want).max())
