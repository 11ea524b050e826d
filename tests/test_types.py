"""What the type checker (mypy, `[tool.mypy]` in pyproject.toml) sees of the structures
built at import: MembraneArrays' typed fields are the core fields the model builds."""

from __future__ import annotations

import ast
from pathlib import Path

import hybrid.model as model


def test_the_typed_membrane_arrays_are_the_core_fields():
    # the class under `if TYPE_CHECKING:` in hybrid/model.py, read from the source
    tree = ast.parse(Path(model.__file__).read_text(encoding="utf-8"))
    (stub,) = [n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == "MembraneArrays"]
    typed = [s.target.id for s in stub.body if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)]
    assert typed == [*model._CORE_BEFORE, *model._CORE_AFTER]
    assert set(typed) <= set(model.MembraneArrays._fields)
