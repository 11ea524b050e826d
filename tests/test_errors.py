"""The exceptions of hybrid (hybrid.errors): one hierarchy under HybridError."""

from __future__ import annotations

from hybrid.errors import ConstraintError, HybridError, MeshError, SceneError, SimulationDiverged


def test_errors_form_a_hierarchy():
    for cls in (MeshError, SceneError, ConstraintError, SimulationDiverged):
        assert issubclass(cls, HybridError)
    assert issubclass(SceneError, ValueError) and issubclass(MeshError, ValueError)
