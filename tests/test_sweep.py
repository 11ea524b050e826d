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
    assert all(r["pid"] != os.getpid() for r in res)  # in worker processes
    assert all(r["numba_threads"] == "1" for r in res)  # no oversubscription
    assert sweep(_square, [3, 1, 2], workers=2) == [9, 1, 4]  # non-dict parameters: fn(p)
    assert sweep(_square, [4], workers=1) == [16] and sweep(_square, []) == []


def test_errors_raise_or_return():
    params = [{"a": 1}, {"a": -1}, {"a": 2}]
    with pytest.raises(SimulationDiverged, match="a = -1") as info:
        sweep(_task, params, workers=2)
    assert info.value.dt_suggested_s == 1e-4 and info.value.step == 7  # attributes survive
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


# ---------------------------------------------------------------- sweeps that survive
import json
import signal
import time

import hybrid
from hybrid.run import RunFailed, run
from hybrid.sweep import TABLE_NAME


def test_run_sweep_returns_every_result_beside_a_diverged_one(tmp_path):
    ok = hybrid.load("membrane_demo")
    bad = hybrid.load("membrane_demo", overrides=["dt_s=0.05"])  # diverges within a few steps
    params = [{"sim": ok, "duration_s": 0.1}, {"sim": bad, "duration_s": 1.0}, {"sim": ok, "duration_s": 0.2}]
    res = sweep(run, params, workers=2, on_error="return", out=tmp_path)
    assert [r["summary"]["status"] for r in (res[0], res[2])] == ["ok", "ok"]
    assert res[2]["summary"]["duration_s"] > res[0]["summary"]["duration_s"]
    assert isinstance(res[1], RunFailed) and isinstance(res[1].error, SimulationDiverged)
    assert res[1].error.dt_suggested_s < 0.05 and res[1].result["summary"]["status"] == "failed"
    assert res[1].sweep_params["duration_s"] == 1.0
    rows = [json.loads(line) for line in (tmp_path / TABLE_NAME).read_text().splitlines()]
    assert sorted(r["status"] for r in rows) == ["failed", "ok", "ok"]
    failed = next(r for r in rows if r["status"] == "failed")
    assert failed["error_type"] == "hybrid.run.RunFailed" and "diverged" in failed["error"]


CALLS = []


def _kill_last(a, table):
    """a task; a == "kill" dies (SIGKILL) once the other three rows are in the table."""
    if a == "kill" and not os.environ.get("HYBRID_TEST_NO_KILL"):
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if os.path.exists(table) and len(open(table).read().splitlines()) >= 3:
                os.kill(os.getpid(), signal.SIGKILL)
            time.sleep(0.05)
    CALLS.append(a)
    return {"a": a}


def test_a_killed_worker_keeps_the_finished_rows_and_a_rerun_skips_them(tmp_path, monkeypatch):
    table = str(tmp_path / TABLE_NAME)
    params = [
        {"a": 1, "table": table},
        {"a": 2, "table": table},
        {"a": "kill", "table": table},
        {"a": 3, "table": table},
    ]
    res = sweep(_kill_last, params, workers=2, on_error="return", out=tmp_path)
    assert [r["a"] for r in (res[0], res[1], res[3])] == [1, 2, 3]
    assert isinstance(res[2], Exception) and res[2].sweep_params["a"] == "kill"  # BrokenProcessPool
    rows = [json.loads(line) for line in open(table).read().splitlines()]
    assert sorted(r["params"]["a"] for r in rows) == [1, 2, 3] and {r["status"] for r in rows} == {"ok"}
    # the rerun runs only the task that was lost
    monkeypatch.setenv("HYBRID_TEST_NO_KILL", "1")
    CALLS.clear()
    again = sweep(_kill_last, params, workers=1, out=tmp_path)
    assert CALLS == ["kill"] and [r["a"] for r in again] == [1, 2, "kill", 3]
    assert len(open(table).read().splitlines()) == 4


# ---------------------------------------------------------------- hybrid sweep
import csv

from hybrid.cli import main
from hybrid.grid import grid_cases, split_values


def test_grid_is_the_product_of_the_comma_lists():
    assert split_values("forces.gravity.accel_m_s2=[0, 0, -9.81],[0,0,0]") == (
        "forces.gravity.accel_m_s2",
        ["[0, 0, -9.81]", "[0,0,0]"],
    )
    cases = grid_cases(["a=1,2", "b=x,y,z"])
    assert len(cases) == 6 and cases[0] == {"a": "1", "b": "x"} and cases[3] == {"a": "2", "b": "x"}


@pytest.mark.parametrize(
    "argv, culprit",
    [
        (["--set", "dt_s"], "expected KEY=V1,V2"),
        (["--set", "dt_s=1e-3,,2e-3"], "no empty value"),
        (["--set", "dt_s=1e-3", "--set", "dt_s=2e-3"], "swept twice"),
        ([], "at least one KEY"),
        (["--set", "no_such_key=1,2"], "no_such_key"),
        (["--set", "dt_s=1e-3,-1"], "dt_s=-1"),
        (["--set", "dt_s=1e-3", "--without", "no_such_term"], "no_such_term"),
        (["--set", "dt_s=1e-3", "--workers", "0"], "--workers"),
    ],
)
def test_bad_sweep_input_is_one_line_and_status_2(tmp_path, capsys, argv, culprit):
    assert main(["sweep", "membrane_demo", *argv, "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hybrid: error:") and culprit in err, err
    assert not (tmp_path / "s").exists()  # refused before the folder is made


def test_sweep_command_writes_table_and_plot_and_a_rerun_skips_what_is_done(tmp_path, capsys):
    out = tmp_path / "s"
    argv = [
        "sweep",
        "membrane_demo",
        "--set",
        "dt_s=1e-3,0.05",
        "--set",
        "masses.total_kg=4,5",
        "--duration",
        "0.2",
        "--out",
        str(out),
        "--workers",
        "1",
    ]
    assert main(argv) == 1  # a run failed: status 1, the others in the table
    rows = list(csv.DictReader(open(out / "sweep.csv")))
    assert [(r["dt_s"], r["masses.total_kg"], r["status"]) for r in rows] == [
        ("1e-3", "4", "ok"),
        ("1e-3", "5", "ok"),
        ("0.05", "4", "failed"),
        ("0.05", "5", "failed"),
    ]
    assert float(rows[0]["volume_rel_error_max"]) < 1e-12 and "diverged" in rows[2]["error"]
    assert (out / "sweep.png").stat().st_size > 1000
    assert "4 runs, 2 failed" in capsys.readouterr().out
    lines = (out / TABLE_NAME).read_text().splitlines()
    assert main(argv) == 1  # the ok rows are skipped, the failed ones run again
    assert len((out / TABLE_NAME).read_text().splitlines()) == len(lines) + 2
    capsys.readouterr()
    assert main([*argv[:-6], "--duration", "0.1", "--out", str(out)]) == 2  # other settings: refused
    assert "holds a sweep of" in capsys.readouterr().err
