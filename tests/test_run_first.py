"""A first run says what it does (issue 15, item 3): on an empty compile cache,
`hybrid run` says on stderr that it compiles before it does; with the kernels cached,
nothing. It compiles the one step loop that every later scene of its integrator's family
loads (issue 30). A sweep runs its first task alone, so that the others load what it
compiled."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hybrid.sweep import sweep

ROOT = Path(__file__).resolve().parents[1]


def _run(cache: Path, out: Path, scene: str = "membrane_demo") -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(cache))
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "hybrid",
            "run",
            scene,
            "--duration",
            "0.01",
            "--no-record",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
    )


# `python -m hybrid run membrane_demo ...` (runpy, as -m runs it) into an empty compile
# cache, then, in the same process, a census of what it compiled: on stdout, after
# the command's own output, so that its stderr is the command's
_COMPILED = """
import json, runpy, sys
sys.argv = ["hybrid", "run", "membrane_demo", "--duration", "0.01", "--no-record", "--out", sys.argv[1]]
try:
    runpy.run_module("hybrid", run_name="__main__", alter_sys=True)
except SystemExit as stop:
    code = stop.code
from hybrid import implicit, loop
from hybrid.terms import lungs, membrane, resting_tension, soft_volume, volume
def cached(dispatcher):  # builds in the disk cache, whichever process compiled them (`hybrid.calls`)
    try:
        return len(dispatcher._cache._cache_file._load_index())
    except OSError:
        return 0
apart = (implicit.implicit_step, implicit.implicit_start_forces, lungs.lungs_step_force, lungs.project_occluded,
         resting_tension.resting_tension_step_force, soft_volume.soft_volume_step)
print(json.dumps({"code": code, "loops": [cached(loop.run_steps), cached(loop.steps_between)],
                  "parallel": [cached(k) for k in (membrane.membrane_faces_parallel, volume.volume_direction_parallel)],
                  "implicit": [cached(k) for k in (implicit.implicit_forces, implicit.newton_caches)],
                  "apart": [cached(k) for k in apart],
                  "rigid": cached(loop.rigid_between)}))
"""

# after the first run, in a new process on its cache: scenes with other terms, a rigid part, the
# paper's formulation and lungs, each stepped; how the step loop came (loaded or compiled)
_OTHER_SCENES = """
import dataclasses, json, hybrid
from hybrid import loop
from hybrid.terms import Pressure
demo = hybrid.load_scene("membrane_demo")
custom = dataclasses.replace(demo, forces=demo.forces[1:] + (Pressure(10.0),))  # no gravity, a pressure
runs = {}
for name, scene in (("breathing_paper", "breathing_paper"), ("breathing_lungs", "breathing_lungs"),
                    ("custom", custom)):
    sim = hybrid.load(scene)
    sim.step(3)
    runs[name] = sorted(n for n, c in sim.term_calls.items() if c)
stats = [k.stats for k in (loop.run_steps, loop.steps_between)]
print(json.dumps({"runs": runs, "hits": [sum(s.cache_hits.values()) for s in stats],
                  "misses": [sum(s.cache_misses.values()) for s in stats]}))
"""


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """The first run of membrane_demo, into an empty compile cache, in a process of its own
    (`_COMPILED`): compiling is most of a test's time here, so both tests of a first run
    read this one."""
    tmp = tmp_path_factory.mktemp("first_run")
    cache = tmp / "cache"
    cache.mkdir()
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(cache))
    proc = subprocess.run(
        [sys.executable, "-c", _COMPILED, str(tmp / "out")], capture_output=True, text=True, env=env, timeout=900
    )
    return {"process": proc, "cache": cache}


def test_a_first_run_says_it_compiles_and_a_second_does_not(first_run, tmp_path):
    cold = first_run["process"]  # `python -m hybrid run` into an empty cache
    assert cold.returncode == 0, cold.stderr
    lines = cold.stderr.splitlines()
    assert re.fullmatch(r"hybrid: compiling kernels for this scene, first run only, about \d+ s of CPU", lines[0]), (
        cold.stderr
    )
    assert lines[-1].startswith("hybrid: compiled in ") and str(first_run["cache"]) in lines[-1]
    assert "Traceback" not in cold.stderr
    warm = _run(first_run["cache"], tmp_path / "b")
    assert warm.returncode == 0 and warm.stderr == ""


def test_a_scene_that_loads_the_cached_loop_announces_no_first_run(first_run, tmp_path):
    # the loop cached by the first run (membrane_demo), the paper's coupled trunk compiles only
    # a few helpers of its rigid part: the notice must not promise the whole compile's minute
    proc = _run(first_run["cache"], tmp_path / "paper", "breathing_paper")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "first run only" not in proc.stderr, proc.stderr
    assert all(line.startswith("hybrid: compiled in ") for line in proc.stderr.splitlines()), proc.stderr


def test_a_first_run_compiles_the_one_step_loop_once_and_no_build_its_scene_cannot_reach(first_run):
    """Issue 30: on an empty compile cache, `hybrid run` compiles the one step loop once, with
    every term (their flags read at run time: `hybrid.switches`), and not what its scene cannot
    reach: membrane_demo (80 points, symplectic Euler, no lungs, resting tension or soft volume)
    neither the multi-core build, nor implicit Euler's solve, nor the kernels of the terms it lacks
    that the loop calls at their addresses (`hybrid.step_work.StepWork`)."""
    proc = first_run["process"]
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.splitlines()[-1])
    assert got["code"] == 0
    assert got["loops"] == [1, 1]  # `run_steps`, and the steps between two stops it calls at their address
    assert got["rigid"] == 0  # no rigid part
    assert got["parallel"] == [0, 0]
    assert got["implicit"] == [0, 0]
    assert got["apart"] == [0] * 6


def test_scenes_with_other_terms_and_a_rigid_part_load_the_first_runs_loop(first_run):
    """Issue 30: after the first run (membrane_demo: four terms, no rigid part), scenes with
    other sets of terms (the paper's coupled trunk, the trunk with lungs, the demo without
    gravity and with a pressure: a set no packaged scene has) load the compiled step loop
    from the cache: no compile of it in their process."""
    # compiles in this process only (`hybrid.calls.compile_elsewhere` off): each would count a miss
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(first_run["cache"]), HYBRID_COMPILE_HELPER="0")
    proc = subprocess.run([sys.executable, "-c", _OTHER_SCENES], capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.splitlines()[-1])
    runs = got["runs"]
    # the three term sets differ from the first run's and from each other
    first = ["damping", "gravity", "muscle", "shape_memory", "volume"]
    assert len({tuple(r) for r in runs.values()} | {tuple(first)}) == 4, runs
    assert "pressure" in runs["custom"] and "gravity" not in runs["custom"]
    assert "lungs" in runs["breathing_lungs"]
    assert got["misses"] == [0, 0] and min(got["hits"]) >= 1, got


def _stamped(i):
    start = time.time()
    time.sleep(0.2)
    return i, start, time.time(), os.getpid()


def test_a_sweeps_first_task_ends_before_the_others_start():
    res = sweep(_stamped, range(5), workers=2)
    assert [r[0] for r in res] == list(range(5))
    assert res[0][2] <= min(r[1] for r in res[1:])
    assert os.getpid() not in {r[3] for r in res}  # every task in a worker


def test_a_first_run_refused_after_its_scene_is_built_is_one_line(tmp_path):
    """A refusal that needs the built scene (here the step count, which needs its dt) comes
    after the scene's helpers compile: on an empty cache the notice waits for the loop, so
    the error stays the command's one line (it was the third of three: "about 32 s of CPU",
    "compiled in 0.2 s", then the error)."""
    cache = tmp_path / "cache"
    cache.mkdir()
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(cache))
    argv = ["run", "membrane_demo", "--duration", "1e7", "--no-record", "--out", str(tmp_path / "o")]
    proc = subprocess.run([sys.executable, "-m", "hybrid", *argv], capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 2
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hybrid: error: --duration"), proc.stderr
    assert any(cache.iterdir())  # premise: the scene's helpers did compile into the empty cache
