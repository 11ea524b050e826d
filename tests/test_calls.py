"""Kernels compiled apart (`hybrid.calls`): the arguments read from the caller's frame, and a
first run's helper process compiling into the disk cache."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def test_a_kernel_reads_its_arguments_from_the_caller_s_frame_as_passed():
    """`args_in_memory` then `args_from_memory`, item by item: the same arrays (their writes
    seen by the caller) and scalars as a direct call; a large tuple's fields loaded one by one."""
    from typing import NamedTuple

    from numba import njit
    from numba.core import types as nb_types

    from hybrid.calls import args_from_memory, args_in_memory, args_type_of, call_at, kernel_address

    class Pack(NamedTuple):
        a: np.ndarray
        b: np.ndarray
        k: float
        flag: bool

    @njit(no_cpython_wrapper=True)
    def callee(args_at, x, args_type):
        p, q = args_from_memory(args_at, 0, args_type), args_from_memory(args_at, 1, args_type)
        for i in range(p.a.shape[0]):
            p.b[i] = p.a[i] * p.k + x + q[i]
        return p.flag

    @njit
    def caller(address, p, q, x):
        args = (p, q)
        at = args_in_memory(args)
        return call_at(address, False, (at, x, args_type_of(args)))

    pack = Pack(np.arange(4.0), np.zeros(4), 2.5, True)
    q = np.array([1.0, -1.0, 0.5, 0.0])
    address = kernel_address(callee, nb_types.boolean, 0, 0.0, __import__("numba").typeof((pack, q)))
    assert caller(address, pack, q, 0.25) is True
    assert np.array_equal(pack.b, pack.a * 2.5 + 0.25 + q)  # exactly: the same arithmetic


_HELPER = """
import json, numpy as np, numba
from hybrid.calls import compile_elsewhere, is_cached
from hybrid.step import _first_nonfinite
types = tuple(numba.typeof(a) for a in (np.zeros((2, 3)), np.zeros((2, 3)), np.int64(0)))
before = is_cached(_first_nonfinite, types)
helper = compile_elsewhere([(_first_nonfinite, types)])
done = helper.wait() if helper is not None else None
after = is_cached(_first_nonfinite, types)
_first_nonfinite.compile(types)
stats = _first_nonfinite.stats
again = compile_elsewhere([(_first_nonfinite, types)])
print(json.dumps({"before": before, "helper": helper is not None, "done": done, "after": after,
                  "misses": sum(stats.cache_misses.values()), "again": again is not None}))
"""


def test_a_helper_process_compiles_a_kernel_into_the_cache_this_process_then_loads(tmp_path):
    """On an empty cache with a second core, `compile_elsewhere` compiles in a helper process; this
    process then loads the build (no compile here), and a build already cached starts no helper.
    With HYBRID_COMPILE_HELPER=0, none starts."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "cache"), HYBRID_COMPILE_HELPER="1")
    run = subprocess.run([sys.executable, "-c", _HELPER], capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    got = json.loads(run.stdout.splitlines()[-1])
    assert got["before"] is False and got["again"] is False
    if len(os.sched_getaffinity(0)) >= 2:  # one core: compiled here, no helper (the premise below)
        assert got == dict(before=False, helper=True, done=True, after=True, misses=0, again=False), got
    env["HYBRID_COMPILE_HELPER"], env["NUMBA_CACHE_DIR"] = "0", str(tmp_path / "cache0")
    run = subprocess.run([sys.executable, "-c", _HELPER], capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    got = json.loads(run.stdout.splitlines()[-1])
    assert got["helper"] is False and got["misses"] == 1
