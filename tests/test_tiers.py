"""The quick tier (`python -m pytest -m "not slow"`): the slow marker is registered and
every entry of conftest's SLOW list names a test file or folder that exists, so that
a renamed file does not fall silently into the quick loop."""

from __future__ import annotations

import tomllib
from pathlib import Path

from conftest import SLOW

TESTS = Path(__file__).resolve().parent


def test_the_slow_marker_is_registered():
    pytest_options = tomllib.loads((TESTS.parent / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert any(m.startswith("slow:") for m in pytest_options["markers"])


def test_every_slow_entry_names_what_exists():
    missing = [s for s in SLOW if not (TESTS / s.split("::")[0]).exists()]
    # a single test: its function is still in its file
    missing += [
        s for s in SLOW if "::" in s and f"def {s.split('::')[1]}(" not in (TESTS / s.split("::")[0]).read_text()
    ]
    assert not missing, missing
