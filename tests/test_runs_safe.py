"""Runs that write only where they are told, keep their folder to themselves, say
how they ended, refuse lengths that cannot run, and give divergence advice that
helps (hybrid.run, hybrid.cli, the recording interval, Simulation's advice)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import hybrid
import hybrid.model
from hybrid.cli import main
from hybrid.demo import membrane_demo
from hybrid.errors import HybridError, SimulationDiverged
from hybrid.record import Recorder, read
from hybrid.regions import HalfSpace
from hybrid.run import default_out, run
from hybrid.scene import Damping, Gravity, Masses, MeshSpec, Nailed, Scene, ShapeMemory, Volume

ROOT = Path(__file__).resolve().parents[1]


def _cli(*args, cwd=None, **kw):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [sys.executable, "-m", "hybrid", *args],
        cwd=cwd,
        env=env,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        **kw,
    )


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _wait_running(folder: Path, proc, timeout_s: float = 120.0) -> dict:
    """The summary of a run once it says "running" (its folder then locked)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            summary = json.loads((folder / "summary.json").read_text())
            if summary["status"] == "running" and (folder / "run.mcap").exists():
                return summary
        except (FileNotFoundError, json.JSONDecodeError):
            pass
        time.sleep(0.1)
    raise AssertionError("the run never started")


# ------------------------------------------------------------------ item 1: the name is a name


@pytest.mark.parametrize(
    "name, why",
    [
        ("../../x", "path separator"),
        ("/elsewhere/x", "path separator"),
        ("..", "'..'"),
        ("a\\b", "path separator"),
        ("", "empty"),
        ("a\0b", "NUL"),
    ],
)
def test_a_scene_name_that_is_a_path_is_refused_as_a_folder(name, why):
    """Item 1: runs/<name> only for a plain name."""
    with pytest.raises(HybridError, match=f"scene name: expected a plain name.*{why}.*--out"):
        default_out(name)
    assert default_out("membrane_demo") == Path("runs") / "membrane_demo"


@pytest.mark.parametrize("name", ["../../x", "/elsewhere/x"])
def test_hybrid_run_writes_nothing_where_a_scene_name_points(name, tmp_path, monkeypatch, capsys):
    """Item 1: --set name=../../x (or an absolute path) is refused with one line, exit 2,
    and nothing is written: not at the path, not in runs/."""
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    name = name.replace("/elsewhere", str(tmp_path / "elsewhere"))
    assert main(["run", "membrane_demo", "--duration", "0.01", "--set", f"name={json.dumps(name)}"]) == 2
    # refused where the scene is checked, before any folder is chosen
    assert "name: expected a plain name" in _one_line(capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a", "b"]


def test_an_empty_out_is_refused(tmp_path, monkeypatch, capsys):
    """Item 1: --out '' is not 'the default folder'."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", "membrane_demo", "--duration", "0.01", "--out", ""]) == 2
    assert "--out: expected a folder, received ''" in _one_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ item 2 and 9: a locked folder, SIGTERM


def _frames_from_zero(t):
    np.testing.assert_allclose(t, np.arange(len(t)) * 0.01, rtol=0, atol=1e-9)


def test_a_second_run_into_a_busy_folder_is_refused_and_sigterm_finishes_the_first(tmp_path):
    """Items 2 and 9: two real processes into one folder: the second exits 2 with one line
    naming the first's process id and touches nothing; SIGTERM then stops the first as
    Ctrl-C does: the recording finished (summary and footer, read by the mcap library),
    summary.json "interrupted" with the time reached."""
    from mcap.reader import make_reader

    out = tmp_path / "shared"
    first = _cli("run", "membrane_demo", "--duration", "100000", "--out", str(out))
    try:
        _wait_running(out, first)
        time.sleep(1.0)  # some frames in the file
        before = (out / "summary.json").read_bytes()
        second = _cli("run", "membrane_demo", "--duration", "0.5", "--out", str(out))
        _, err = second.communicate(timeout=300)
        assert second.returncode == 2
        line = _one_line(err)
        assert f"in use by hybrid run process {first.pid}" in line and str(out) in line
        assert (out / "summary.json").read_bytes() == before
        assert first.poll() is None
        first.send_signal(signal.SIGTERM)
        _, err = first.communicate(timeout=120)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 128 + signal.SIGTERM
    assert "interrupted by SIGTERM" in _one_line(err)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    assert 0 < summary["duration_s"] < 100000 and summary["steps"] == round(summary["duration_s"] / 1e-3)
    with open(out / "run.mcap", "rb") as f:
        reader = make_reader(f)
        info = reader.get_summary()  # a finished file: summary and footer
        assert info is not None and info.statistics.message_count > 0
    t = read(out / "run.mcap")["membrane"]["t"]
    _frames_from_zero(t)  # the first's frames only, every one from 0
    assert t[-1] == pytest.approx(summary["duration_s"], abs=0.01 + 1e-9)
    assert (out / "membrane_demo.png").stat().st_size > 10_000


def test_sighup_stops_a_run_as_ctrl_c_does(tmp_path):
    """Item 9: SIGHUP (a closed terminal) too: a finished recording and an interrupted summary."""
    out = tmp_path / "o"
    proc = _cli("run", "membrane_demo", "--duration", "100000", "--out", str(out))
    try:
        _wait_running(out, proc)
        time.sleep(0.5)
        proc.send_signal(signal.SIGHUP)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGHUP
    assert "interrupted by SIGHUP" in _one_line(err)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["duration_s"] > 0
    _frames_from_zero(read(out / "run.mcap")["membrane"]["t"])


def test_a_rerun_into_a_folder_that_holds_a_run_is_refused_unless_overwrite(tmp_path, capsys):
    """Issue 15, item 5: an explicit --out that holds a run is refused, one line, and left as it was."""
    out = tmp_path / "o"
    assert main(["run", "membrane_demo", "--duration", "0.05", "--no-record", "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def built(*_args, **_kw):
        raise AssertionError("the scene was built before --out was refused")

    # refused before the scene is built or its kernels compile (a first run waited for them)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(hybrid.model, "compile_scene", built)
        assert main(["run", "membrane_demo", "--duration", "0.1", "--out", str(out)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "holds no earlier run" in line and str(out) in line and "--overwrite" in line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert main(["run", "membrane_demo", "--duration", "0.1", "--no-record", "--overwrite", "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["steps"] == 100


def test_a_failed_rerun_replaces_the_earlier_summary(tmp_path, capsys):
    """Item 9: a run (with --overwrite) that cannot write its recording leaves "failed",
    not the last run's "ok"."""
    out = tmp_path / "o"
    assert main(["run", "membrane_demo", "--duration", "0.05", "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["status"] == "ok"
    (out / "run.mcap").unlink()
    (out / "run.mcap").mkdir()  # the recording cannot be opened
    # issue 31: a file that cannot be written is the file system's doing: EX_IOERR, not 2
    assert main(["run", "membrane_demo", "--duration", "0.05", "--overwrite", "--out", str(out)]) == 74
    line = _one_line(capsys.readouterr().err)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and "run.mcap" in summary["error"] and "run.mcap" in line


def test_an_interrupted_run_writes_its_summary(tmp_path, monkeypatch, capsys):
    """Item 9: Ctrl-C in the middle of a run: "interrupted", the time reached, the plot."""
    import importlib

    runner = importlib.import_module("hybrid.run")
    real = runner.run

    def interrupted_run(sim, duration_s, **kw):
        def stop(s, trace):
            if s.steps_done >= 250:
                raise KeyboardInterrupt

        return real(sim, duration_s, **{**kw, "observers": [*kw["observers"], stop]})

    monkeypatch.setattr(runner, "run", interrupted_run)
    # the same run, short, first (with its observer it steps frame by frame): a first
    # compile's notice on stderr is not what this test reads
    assert main(["run", "membrane_demo", "--duration", "0.002", "--out", str(tmp_path / "first")]) == 0
    capsys.readouterr()
    out = tmp_path / "o"
    assert main(["run", "membrane_demo", "--duration", "1", "--out", str(out)]) == 130
    assert "interrupted by SIGINT at t = 0.25 s" in _one_line(capsys.readouterr().err)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["duration_s"] == pytest.approx(0.25)
    assert summary["steps"] == 250 and summary["duration_requested_s"] == 1.0
    assert read(out / "run.mcap")["membrane"]["t"][-1] == pytest.approx(0.25)


def test_a_load_error_leaves_no_folder(tmp_path, capsys):
    """Item 9: a scene that does not compile fails before the output folder exists."""
    out = tmp_path / "new"
    assert main(["run", "membrane_demo", "--dt", "-1", "--out", str(out)]) == 2
    assert "dt_s" in _one_line(capsys.readouterr().err)
    assert not out.exists()


# ------------------------------------------------------------------ items 7 and 10: lengths that cannot run


@pytest.mark.parametrize(
    "args, expected",
    [
        (["--duration", "inf"], "--duration: expected a finite time > 0 s, received inf"),
        (["--duration", "nan"], "--duration: expected a finite time > 0 s, received nan"),
        (["--duration", "1e20"], "expected at most 2^53"),
        (["--dt", "1e-300"], "expected at most 2^53"),
        (["--dt", "1e-9"], "is 4e+09 steps, more than 1e+08; add --yes to run them"),
        (["--duration", "1e-4"], "--duration 0.0001 s: expected at least one step of dt_s = 0.001 s"),
        (["--set", "dt_s=1e300"], "dt_s: expected a number > 0 and <= 1000"),  # past the physical bound
    ],
)
def test_run_lengths_that_cannot_run_are_one_line(args, expected, tmp_path, monkeypatch, capsys):
    """Items 7 and 10: each one line, exit 2, nothing written."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", "membrane_demo", "--duration", "4", *args]) == 2
    assert expected in _one_line(capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


def test_more_than_1e8_steps_run_with_yes(tmp_path):
    """Item 10: --yes confirms; the run starts (stopped here after its first frames)."""
    out = tmp_path / "o"
    proc = _cli("run", "membrane_demo", "--dt", "1e-9", "--yes", "--no-record", "--out", str(out))
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and not (out / "summary.json").exists():
            time.sleep(0.1)
        assert proc.poll() is None and (out / "summary.json").exists()
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130
    assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"


# ------------------------------------------------------------------ item 6: flat memory


_PEAK = """
import resource, sys
from hybrid.cli import main
code = main(["run", "membrane_demo", "--duration", sys.argv[1], "--no-record", "--out", sys.argv[2]])
print(code, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def _peak_kib(duration_s: float, out: Path) -> int:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run(
        [sys.executable, "-c", _PEAK, str(duration_s), str(out)], capture_output=True, text=True, env=env, timeout=900
    )
    code, kib = proc.stdout.splitlines()[-1].split()
    assert code == "0", proc.stderr
    return int(kib)


def test_the_runners_memory_does_not_grow_with_the_runs_length(tmp_path):
    """Item 6: 1e6 steps hold the peak memory of 1e5 (the trace was 34 MB per 1e6
    steps; 10x the steps would add about 30 MB, three times the bound)."""
    short = _peak_kib(100.0, tmp_path / "short")
    long = _peak_kib(1000.0, tmp_path / "long")
    assert long - short < 10 * 1024, (short, long)
    summary = json.loads((tmp_path / "long" / "summary.json").read_text())
    assert summary["steps"] == 1_000_000 and summary["volume_rel_error_max"] < 1e-12
    # the streamed trace's file is gone with the run
    assert {p.name for p in (tmp_path / "long").iterdir()} == {"membrane_demo.png", "summary.json", ".hybrid-run.lock"}


def test_a_streamed_trace_reads_back_as_the_one_in_memory(tmp_path):
    """Item 6: the trace streamed to a file (as hybrid run does) equals the one kept in memory."""
    kept = run(hybrid.load(membrane_demo()), 30.0)
    with open(tmp_path / "spill", "w+b") as spill:
        streamed = run(hybrid.load(membrane_demo()), 30.0, trace_spill=spill)
        a, b = kept["trace"].arrays(), streamed["trace"].arrays()
        assert len(a["t_s"]) == 3001
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        env = streamed["trace"].envelope(100)
        assert 100 < len(env["t_s"]) <= 200
        assert env["pressure_pa"].max() == a["pressure_pa"].max()
        assert env["pressure_pa"].min() == a["pressure_pa"].min()
    sa, sb = dict(kept["summary"]), dict(streamed["summary"])
    for s in (sa, sb):
        del s["wall_s"], s["us_per_step"], s["provenance"]["started_utc"]
    assert sa == sb


# ------------------------------------------------------------------ item 11: advice that helps


def _sphere(integrator, forces, dt_s=1e-3, m=0.05):
    return Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(per_vertex_kg=(m,) * 80),
        regions={"bottom": HalfSpace((0.0, 0.0, -0.1), (0.0, 0.0, -1.0))},
        forces=forces,
        constraints=(Nailed("bottom"), Volume()),
        dt_s=dt_s,
        integrator=integrator,
    )


def _diverge(scene, steps=20000) -> SimulationDiverged:
    sim = hybrid.load(scene)
    with pytest.raises(SimulationDiverged) as caught:
        sim.step(steps)
    return caught.value


def test_undamped_explicit_euler_is_not_told_to_shrink_the_step():
    """Item 11: explicit Euler on an undamped spring grows by sqrt(1 + h^2 k/m) a step
    whatever h: the advice is damping (shape memory excites itself under symplectic
    Euler too), and no step is suggested."""
    err = _diverge(_sphere("explicit_euler", (Gravity(), ShapeMemory(3000.0))))
    msg = str(err)
    assert "no smaller step helps; add Damping(critical_fraction=0.3)" in msg
    assert "try dt_s" not in msg and math.isnan(err.dt_suggested_s)
    # the advice holds: the same step with that damping runs
    hybrid.load(_sphere("explicit_euler", (Gravity(), ShapeMemory(3000.0), Damping(critical_fraction=0.3)))).step(20000)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "explicit_euler"])
def test_a_stiffness_beyond_any_step_is_told_to_lower_the_stiffness(integrator):
    """Item 11: where the stability estimate resolves no step (0; the issue's stiffness 1e30
    is now refused at load, past the 1e12 N/m bound: the same ratio k/m = 2e31 /s^2 with
    the stiffest allowed tissue and 5e-20 kg points): the advice is the closed-form bound
    and to lower the stiffness, not a quarter of the step."""
    k, m = 1e12, 5e-20
    err = _diverge(_sphere(integrator, (Gravity(), ShapeMemory(k), Damping(critical_fraction=0.3)), m=m))
    msg = str(err)
    assert "lower the stiffness" in msg and "0.00025" not in msg and "try dt_s" not in msg
    # symplectic: 2 sqrt(m/k) = 4.5e-16 s; damped explicit: c/k = 0.3 * 2 sqrt(k m) / k = 1.3e-16 s
    bound = 2 * math.sqrt(m / k) if integrator == "symplectic_euler" else 0.6 * math.sqrt(m / k)
    assert err.dt_suggested_s == pytest.approx(0.5 * bound, rel=0.05)
    stated = re.search(r"a stable step would be about ([0-9.e+-]+) s", msg)
    assert stated is not None and float(stated.group(1)) == pytest.approx(bound, rel=0.05)


def test_free_fall_of_a_small_body_is_not_a_runaway():
    """Item 11: a 1 cm sphere (its bounding box's diagonal 17 mm) falls freely for 2.5 s,
    to 24.5 m/s or 24.5 mm a step: not a divergence (the body's size called it one
    after 1.8 s). Symplectic Euler's discrete fall z_n = -g h^2 n (n + 1) / 2 to rounding."""
    scene = Scene(
        formulation="paper",
        mesh=MeshSpec(radius_m=0.005),
        masses=Masses(total_kg=0.01),
        forces=(Gravity(),),
        constraints=(Volume(),),
        dt_s=1e-3,
    )
    sim = hybrid.load(scene)
    n = 2500
    sim.step(n)
    dz = sim.vert_pos[:, 2] - sim.model.mesh.vert_pos[:, 2]
    np.testing.assert_allclose(dz, -9.81 * 1e-6 * n * (n + 1) / 2, rtol=1e-9)
    # a runaway is still caught, by max_speed: the same fall past 50 m/s
    with pytest.raises(SimulationDiverged, match="above max_speed_m_s = 50"):
        sim.step(5000)


def test_a_recording_interval_that_is_not_a_whole_number_of_steps_is_refused(tmp_path, capsys):
    """Item 11: dt 2.3 ms and 10 ms: refused, naming the steps that divide (2.5 and 2 ms)
    and the intervals that fit (9.2 and 11.5 ms); it recorded frames 18.4 ms apart."""
    sim = hybrid.load(dataclasses.replace(membrane_demo(), dt_s=2.3e-3))
    with pytest.raises(
        HybridError,
        match=r"every_s: expected a whole number of steps of dt_s = 0.0023 s, received "
        r"0.01 s \(4.34783 steps\); a step dt_s = 0.0025 s or 0.002 s \(4 or 5 steps\) "
        r"divides it, or record every 0.0092 s or 0.0115 s",
    ):
        Recorder(tmp_path / "r.mcap", sim, every_s=0.01)
    out = tmp_path / "o"
    assert (
        main(
            ["run", "membrane_demo", "--dt", "0.0023", "--record-every", "0.01", "--duration", "0.1", "--out", str(out)]
        )
        == 2
    )
    assert "--record-every: expected a whole number of steps" in _one_line(capsys.readouterr().err)
    assert not out.exists()
    # without --record-every: the steps nearest 10 ms, frames exactly that far apart
    assert main(["run", "membrane_demo", "--dt", "0.0023", "--duration", "0.5", "--out", str(out)]) == 0
    t = read(out / "run.mcap")["membrane"]["t"]
    np.testing.assert_allclose(np.diff(t), 4 * 2.3e-3, rtol=1e-9)


def test_the_recording_interval_is_honoured_exactly(tmp_path):
    """Item 11: 15 ms at dt 1 ms, the runner's frames 10 ms apart: frames every 15 ms
    (they were 20 ms apart), each frame's scalars those of the trace at that time."""
    sim = hybrid.load(membrane_demo())
    with Recorder(tmp_path / "r.mcap", sim, every_s=0.015) as rec:
        result = run(sim, 0.6, observers=[rec])
    data = read(tmp_path / "r.mcap")
    np.testing.assert_allclose(data["membrane"]["t"], np.arange(41) * 0.015, rtol=0, atol=1e-9)
    trace = result["trace"].arrays()
    rows = np.searchsorted(trace["t_s"], data["/pressure"]["t"] - 1e-9)
    np.testing.assert_array_equal(data["/pressure"]["value"], trace["pressure_pa"][rows])
