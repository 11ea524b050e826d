"""A sweep that is stopped ends (issue 31, items 2, 3 and 7): Ctrl-C to its process group
and SIGTERM to its main process leave no process alive within 10 s, the finished rows
readable in sweep.jsonl, one line said and no worker traceback; two sweeps into one
folder do not both run (real processes, as tests/test_runs_safe.py does for runs)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: two cases that diverge at once (finished rows) and two that run for hours
ARGV = ["--set", "dt_s=0.05,1e-3", "--set", "masses.total_kg=4,5", "--duration", "100000", "--workers", "2"]


def _sweep(out: Path, *extra) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [sys.executable, "-m", "hybrid", "sweep", "membrane_demo", *ARGV, *extra, "--out", str(out)],
        env=env,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,  # its own process group, as a shell job
    )


def _rows(out: Path) -> list:
    try:
        text = (out / "sweep.jsonl").read_text()
    except FileNotFoundError:
        return []
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def _wait_rows(out: Path, proc, n: int, timeout_s: float = 300.0) -> None:
    """Until the table holds n rows and the long cases run in their workers."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        if len(_rows(out)) >= n:
            time.sleep(3.0)  # the long cases under way
            return
        time.sleep(0.3)
    pytest.fail(f"{n} rows not written in {timeout_s} s")


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _stopped(proc, pgid: int, send) -> tuple[str, float]:
    """Send the signal; (stderr, seconds until no process of the group is left)."""
    t0 = time.monotonic()
    send()
    try:
        try:
            _, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            err = "(still running)"
        while _group_alive(pgid) and time.monotonic() - t0 < 60:
            time.sleep(0.1)
        return err, time.monotonic() - t0
    finally:
        if _group_alive(pgid):
            os.killpg(pgid, signal.SIGKILL)


@pytest.mark.parametrize("how", ["SIGINT to the group", "SIGTERM to the main process"])
def test_a_stopped_sweep_ends_its_workers_keeps_its_rows_and_says_one_line(tmp_path, how):
    out = tmp_path / "sw"
    proc = _sweep(out)
    pgid = proc.pid
    try:
        _wait_rows(out, proc, 2)
    except BaseException:
        os.killpg(pgid, signal.SIGKILL)
        raise
    if how.startswith("SIGINT"):
        err, took = _stopped(proc, pgid, lambda: os.killpg(pgid, signal.SIGINT))
        sig = signal.SIGINT
    else:
        err, took = _stopped(proc, pgid, lambda: proc.send_signal(signal.SIGTERM))
        sig = signal.SIGTERM
    assert took < 10.0, f"processes left {took:.1f} s after {how}"
    assert proc.returncode == 128 + sig
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"interrupted by {sig.name}" in lines[0] and "sweep.jsonl" in lines[0]
    rows = _rows(out)
    assert len(rows) == 2 and {r["params"]["dt_s"] for r in rows} == {"0.05"}
    assert all(r["status"] == "failed" and "diverged" in r["error"] for r in rows)


def test_a_second_sweep_into_a_busy_folder_is_refused(tmp_path):
    out = tmp_path / "sw"
    first = second = None
    first = _sweep(out)
    try:
        _wait_rows(out, first, 2)
        second = _sweep(out)
        _, err = second.communicate(timeout=300)
        assert second.returncode == 2
        lines = err.strip().splitlines()
        assert len(lines) == 1 and f"in use by hybrid sweep process {first.pid}" in lines[0], err
        assert len(_rows(out)) == 2  # nothing run twice
    finally:  # neither sweep left running, whatever failed (a second that runs is a sweep of hours)
        for proc in (first, second):
            if proc is not None and _group_alive(proc.pid):
                os.killpg(proc.pid, signal.SIGKILL)
            if proc is not None:
                proc.communicate()
