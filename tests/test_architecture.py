"""docs/architecture.md's worked example holds: the two edits it shows, applied
to a copy of the package, give a working new term (scene vocabulary, scene file,
compiled step)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"


def _blocks() -> dict:
    """The doc's python blocks by their first line, '# edit N: path[, where]'."""
    out = {}
    for body in re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S):
        head, _, code = body.partition("\n")
        if head.startswith("# edit"):
            out[head[2:].strip()] = code
    return out


def _insert_after(text: str, anchor: str, new: str) -> str:
    assert text.count(anchor) == 1, anchor
    return text.replace(anchor, anchor + new)


def test_adding_a_term_takes_the_two_edits_the_architecture_page_shows(tmp_path):
    blocks = _blocks()
    assert {k.split(":")[0] for k in blocks} == {"edit 1", "edit 2"}
    pkg = tmp_path / "hybrid"
    shutil.copytree(ROOT / "hybrid", pkg, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "models", tmp_path / "models")

    # edit 1: the module, as the page gives it
    (pkg / "terms" / "floor.py").write_text(blocks["edit 1: hybrid/terms/floor.py"])
    # edit 2: the import beside the others, the class at the end of order_terms
    init = (pkg / "terms" / "__init__.py").read_text()
    edit2 = blocks["edit 2: hybrid/terms/__init__.py"]
    init = _insert_after(init, "from .local import KeepIn, Nailed, Prescribed\n", edit2.splitlines()[0] + "\n")
    tuple_text = re.search(r"order_terms\(\(.*?\)\)", edit2, re.S).group(0)
    init = re.sub(r"order_terms\(\s*\(.*?\),?\s*\)\n", tuple_text + "\n", init, count=1, flags=re.S)
    (pkg / "terms" / "__init__.py").write_text(init)

    # a sphere dropped on the floor, written as a scene file: it comes to rest on it
    script = """
import numpy as np
import hybrid
from hybrid import scenefile
from hybrid.terms import TERMS
scene = scenefile.scene_from_dict({
    "formulation": "paper",
    "mesh": {"generator": "icosphere", "subdivisions": 1, "radius_m": 0.1, "center_m": [0, 0, 0.1]},
    "masses": {"total_kg": 1.0},
    "forces": [{"type": "gravity"}, {"type": "shape_memory", "stiffness_n_per_m": 500.0},
               {"type": "damping", "critical_fraction": 0.5},
               {"type": "floor", "stiffness_n_per_m": 2000.0}],
    "constraints": [{"type": "volume"}], "dt_s": 5e-4})
sim = hybrid.load(scene)
sim.step(2000)  # 1 s
print("floor" in TERMS, sim.term_calls["floor"], float(sim.vert_pos[:, 2].min()), sim.volume_rel_error)
"""
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    known, calls, z_min, vol_err = proc.stdout.split()
    assert known == "True" and int(calls) == 2000
    # at rest the floor carries the weight: 9.81 N spread over the few points in
    # contact at 2000 N/m each sinks them by millimetres, not the 4.9 m of a free fall
    assert -0.02 < float(z_min) < 0.0
    assert float(vol_err) < 1e-12
