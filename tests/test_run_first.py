"""A first run says what it does (issue 15, item 3): on an empty compile cache,
`hybrid run` says on stderr that it compiles before it does; with the kernels cached,
nothing. A sweep runs its first task alone, so that the others load what it compiled."""

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


def _run(cache: Path, out: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(cache))
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "hybrid",
            "run",
            "membrane_demo",
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
import hybrid
from hybrid import loop, step
from hybrid.terms import fibres, local, lungs, membrane, muscle, passive_fibres, shape_memory, springs, volume
kernels = {  # each switch of the step: the kernels it guards
    "shape_memory": [shape_memory.shape_memory_frames, shape_memory.shape_memory_frames_parallel],
    "membrane": [membrane.add_membrane_serial, membrane.membrane_faces_parallel, membrane.membrane_gather_parallel],
    "applied": [springs.add_applied], "attraction": [springs.add_attraction], "mass_spring": [springs.add_mass_spring],
    "muscle": [muscle.add_muscle], "soft_volume": [volume.soft_volume_force], "pressure": [volume.add_pressure],
    "fibres": [fibres.add_muscle_fibres], "passive": [passive_fibres.add_passive_fibres], "prescribed": [local.apply_prescribed], "keep_in": [local.apply_keep_in],
    "volume": [volume.project_volume],
    "shake": [volume.volume_direction_serial, volume.volume_direction_parallel],
    "lungs": [lungs.add_cavity_pressure], "lungs_held": [lungs.project_occluded],
}
names = list(step.FORCE_SWITCHES) + list(step.ADVANCE_SWITCHES)
switches = step.step_switches(hybrid.load("membrane_demo").model.arrays)[1:]
print(json.dumps({"code": code, "loops": {k.py_func.__name__: len(k.signatures) for k in
                  (loop.run_steps,)},
                  "kernels": {name: [len(k.signatures) for k in kernels[name]] for name in names},
                  "on": {name: on is not None for name, on in zip(names, switches)}}))
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


def test_a_first_run_compiles_only_the_kernels_its_scene_uses(first_run):
    """Issue 15: on an empty compile cache, `hybrid run` compiles the kernels of the
    terms its scene has and no other (their branches are pruned when the step
    compiles: `hybrid.step.step_switches`), and the one step loop once."""
    proc = first_run["process"]
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(proc.stdout.splitlines()[-1])
    assert got["code"] == 0
    assert got["loops"] == {"run_steps": 1}  # the one step loop, once: a membrane-only scene
    on = got["on"]
    # membrane_demo: shape memory, muscle, nailed points and the volume constraint; no other term
    assert {name for name, used in on.items() if used} == {"shape_memory", "muscle", "volume"}
    for name, counts in got["kernels"].items():
        if on[name]:  # the serial build of a small scene, not the parallel twins
            assert counts[0] == 1 and sum(counts) == 1, (name, counts)
        else:
            assert sum(counts) == 0, (name, counts)


def _stamped(i):
    start = time.time()
    time.sleep(0.2)
    return i, start, time.time(), os.getpid()


def test_a_sweeps_first_task_ends_before_the_others_start():
    res = sweep(_stamped, range(5), workers=2)
    assert [r[0] for r in res] == list(range(5))
    assert res[0][2] <= min(r[1] for r in res[1:])
    assert os.getpid() not in {r[3] for r in res}  # every task in a worker
