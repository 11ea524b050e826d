"""hybrid.sweep: parameter sets in parallel, results in order, locally and on Dask."""

import os

import pytest

from hybrid.errors import SimulationDiverged
from hybrid.sweep import sweep


def _task(a, b=0):
    if a < 0:
        raise SimulationDiverged(f"a = {a}", time_s=0.5, step=7, vert=3, dt_suggested_s=1e-4)
    return {"a": a, "ab": a * 10 + b, "pid": os.getpid(), "numba_threads": os.environ.get("NUMBA_NUM_THREADS")}


def _square(x):
    return x * x


PARAMS = [{"a": a, "b": b} for a, b in [(3, 1), (0, 2), (5, 0), (1, 1), (4, 4), (2, 9)]]


WANT = [a * 10 + b for a, b in [(3, 1), (0, 2), (5, 0), (1, 1), (4, 4), (2, 9)]]


def test_local_processes_in_order():
    res = sweep(_task, PARAMS, workers=2)
    assert [r["ab"] for r in res] == WANT
    assert all(r["pid"] != os.getpid() for r in res)       # in worker processes
    assert all(r["numba_threads"] == "1" for r in res)       # no oversubscription
    assert sweep(_square, [3, 1, 2], workers=2) == [9, 1, 4]  # non-dict parameters: fn(p)
    assert sweep(_square, [4], workers=1) == [16] and sweep(_square, []) == []


def test_errors_raise_or_return():
    params = [{"a": 1}, {"a": -1}, {"a": 2}]
    with pytest.raises(SimulationDiverged, match="a = -1") as info:
        sweep(_task, params, workers=2)
    assert info.value.dt_suggested_s == 1e-4 and info.value.step == 7   # attributes survive
    res = sweep(_task, params, workers=2, on_error="return")
    assert res[0]["ab"] == 10 and res[2]["ab"] == 20
    assert isinstance(res[1], SimulationDiverged) and res[1].vert == 3
    with pytest.raises(ValueError, match="on_error"):
        sweep(_task, params, on_error="ignore")


def test_dask_local_cluster_same_results(dask_cluster):
    res = sweep(_task, PARAMS, scheduler=dask_cluster.scheduler_address)
    assert [r["ab"] for r in res] == WANT
    assert len({r["pid"] for r in res} - {os.getpid()}) >= 1
    out = sweep(_task, [{"a": 2}, {"a": -5}], scheduler=dask_cluster.scheduler_address, on_error="return")
    assert out[0]["ab"] == 20 and isinstance(out[1], SimulationDiverged) and out[1].step == 7
