"""A first run says what it does (issue 15, item 3): on an empty compile cache,
`hybrid run` says on stderr that it compiles before it does; with the kernels cached,
nothing. A sweep runs its first task alone, so that the others load what it compiled."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

from hybrid.sweep import sweep

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
    assert re.fullmatch(r"hybrid: compiling kernels for this scene, first run only, about \d+ s", lines[0]), \
        cold.stderr
    assert lines[-1].startswith("hybrid: compiled in ") and str(cache) in lines[-1]
    assert "Traceback" not in cold.stderr
    warm = _run(cache, tmp_path / "b")
    assert warm.returncode == 0 and warm.stderr == ""


def _stamped(i):
    start = time.time()
    time.sleep(0.2)
    return i, start, time.time(), os.getpid()


def test_a_sweeps_first_task_ends_before_the_others_start():
    res = sweep(_stamped, range(5), workers=2)
    assert [r[0] for r in res] == list(range(5))
    assert res[0][2] <= min(r[1] for r in res[1:])
    assert os.getpid() not in {r[3] for r in res}  # every task in a worker
