"""A first run says what it does (issue 15, item 3): on an empty compile cache,
`hybrid run` says on stderr that it compiles before it does; with the kernels cached,
nothing."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(cache: Path, out: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(cache))
    return subprocess.run([sys.executable, "-m", "hybrid", "run", "membrane_demo", "--duration", "0.01",
                           "--no-record", "--out", str(out)], capture_output=True, text=True, env=env, timeout=900)


def test_a_first_run_says_it_compiles_and_a_second_does_not(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    cold = _run(cache, tmp_path / "a")
    assert cold.returncode == 0, cold.stderr
    lines = cold.stderr.splitlines()
    assert lines[0] == "hybrid: compiling kernels for this scene, first run only, about 20 s", cold.stderr
    assert lines[-1].startswith("hybrid: compiled in ") and str(cache) in lines[-1]
    assert "Traceback" not in cold.stderr
    warm = _run(cache, tmp_path / "b")
    assert warm.returncode == 0 and warm.stderr == ""
