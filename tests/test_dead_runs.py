"""A summary cannot lie about a dead run (issue 31, item 5): after SIGKILL, `hybrid.read`,
`hybrid render` and a rerun into the folder say the run was interrupted, not running;
and `hybrid.read` refuses in one line what is no recording."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest

import hybrid
from hybrid.cli import main
from hybrid.errors import HybridError
from hybrid.outputs import run_status
from hybrid.record import RecordingError, RecordingWarning

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def killed_run(tmp_path_factory):
    """A run's folder after SIGKILL, its summary still saying "running"."""
    out = tmp_path_factory.mktemp("killed") / "o"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [sys.executable, "-m", "hybrid", "run", "membrane_demo", "--duration", "100000", "--out", str(out)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            assert proc.poll() is None
            try:
                running = json.loads((out / "summary.json").read_text())["status"] == "running"
            except (OSError, ValueError):
                running = False
            if running and (out / "run.mcap").exists():
                break
            time.sleep(0.2)
        time.sleep(2.0)  # a chunk or two in the recording
        assert run_status(out)["status"] == "running"  # alive: its lock held
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert json.loads((out / "summary.json").read_text())["status"] == "running"  # what the file says
    return out, proc.pid


def test_a_killed_run_is_reported_interrupted_by_run_status_and_read(killed_run):
    out, pid = killed_run
    status = run_status(out)
    assert status["status"] == "interrupted" and str(pid) in status["died"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        data = hybrid.read(out / "run.mcap")
    assert len(data["membrane"]["t"]) > 0
    said = [str(w.message) for w in caught if issubclass(w.category, RecordingWarning)]
    assert any("interrupted" in s and str(pid) in s for s in said), said


def test_a_killed_run_is_reported_interrupted_by_render_and_a_rerun(killed_run, tmp_path, capsys):
    out, pid = killed_run
    assert main(["render", str(out / "run.mcap"), "--out", str(tmp_path / "fig")]) == 0
    err = capsys.readouterr().err
    assert "interrupted" in err and str(pid) in err, err
    assert main(["run", "membrane_demo", "--duration", "0.01", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "interrupted" in err[0] and str(pid) in err[0], err


@pytest.mark.parametrize("size", [0, 8])
def test_read_refuses_a_file_that_holds_no_record_when_strict(tmp_path, size):
    path = tmp_path / "run.mcap"
    path.write_bytes(b"\x89MCAP0\r\n"[:size])
    with pytest.raises(RecordingError, match=f"{size} bytes"):
        hybrid.read(path, strict=True)


@pytest.mark.parametrize(
    "arg, said",
    [("missing.mcap", "does not exist"), (".", "a folder"), (123, "int")],
)
def test_read_of_what_is_no_recording_is_one_hybrid_error(tmp_path, monkeypatch, arg, said):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(HybridError, match=said) as info:
        hybrid.read(arg)
    assert "\n" not in str(info.value) and "path" in str(info.value)
