"""The scene dataclasses (hybrid.scene): removing terms by name."""

from __future__ import annotations

import pytest
from helpers import BASE

from hybrid.errors import SceneError


def test_scene_without_an_unknown_term():
    with pytest.raises(
        SceneError,
        match=r"without: no term named 'muscle' in scene 'scene'; terms: "
        r"\['gravity', 'shape_memory', 'damping', 'nailed', 'volume'\]",
    ):
        BASE.without("muscle")
    assert BASE.without("volume").term_names() == ["gravity", "shape_memory", "damping", "nailed"]
