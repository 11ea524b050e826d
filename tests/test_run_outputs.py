"""What a run's outputs say (issue 15, items 4 and 5): no metric of a part the scene
lacks, the volume's actual change without the constraint, each series' min and max
with their times, the plot named after the scene, the provenance table, and a rerun
that leaves the earlier run's folder alone."""

from __future__ import annotations

import dataclasses
import json
import tomllib

import numpy as np
import pytest

import hybrid
from hybrid.cli import main
from hybrid.record import read
from hybrid.run import METRIC_KEYS, TRACE_KEYS, Trace, metric_table
from hybrid.scenefile import scene_from_dict

PROVENANCE_KEYS = {
    "version",
    "git_commit",
    "command",
    "scene_toml",
    "overrides",
    "without",
    "integrator",
    "dt_s",
    "threads",
    "machine",
}


def _summary(out):
    return json.loads((out / "summary.json").read_text())


def test_without_volume_the_summary_gives_the_change_and_no_error_nor_pressure(tmp_path):
    """`hybrid run --without volume`: volume_rel_error_max null, the actual change
    (6.4% after 1 s), no pressure; the recording has no /volume_rel_error nor /pressure."""
    out = tmp_path / "o"
    assert main(["run", "--without", "volume", "--duration", "1", "--out", str(out)]) == 0
    s = _summary(out)
    assert s["volume_rel_error_max"] is None
    assert s["volume_rel_change_max"] > 0.01
    assert s["volume_rel_change_max"] == s["metrics"]["volume_rel_change"]["max"]
    assert not [key for key in s if key.startswith("pressure")]
    assert not {"pressure_pa", "volume_rel_error"} & set(s["metrics"])
    assert s["rib_lift_mm"] == s["metrics"]["rib_lift_mm"]["max"]  # the ribs are there
    data = read(out / "run.mcap")
    assert "/volume_rel_error" not in data and "/pressure" not in data
    assert len(data["/volume"]["t"]) == len(data["membrane"]["t"]) == 101
    v0 = data["/volume"]["value"][0]
    change = np.abs(data["/volume"]["value"] - v0) / v0
    assert change.max() == pytest.approx(s["volume_rel_change_max"], rel=1e-12)
    assert (out / "breathing.png").exists()


def test_a_scene_without_ribs_has_no_rib_metrics(tmp_path):
    """`hybrid run membrane_demo`: nothing about ribs in the summary, the recording or
    the command's line; the plot is membrane_demo.png."""
    out = tmp_path / "o"
    assert main(["run", "membrane_demo", "--duration", "0.2", "--out", str(out)]) == 0
    s = _summary(out)
    assert not [key for key in s if "rib" in key] and not [key for key in s["metrics"] if "rib" in key]
    assert s["volume_rel_error_max"] < 1e-12 and s["pressure_max_pa"] > 0
    assert "/rib_elevation" not in read(out / "run.mcap")
    assert sorted(p.name for p in out.glob("*.png")) == ["membrane_demo.png"]


def test_each_series_gives_its_min_max_and_their_times():
    """A rib lift falling to -150 mm after rising to 2 mm: min -150 at its time, max 2 at
    its time (the first frame reaching it); a series of NaN (a part the scene lacks) is
    left out."""
    trace = Trace(4)
    t = np.arange(8) * 0.5
    rib = np.array([0.0, 2.0, 2.0, -10.0, -150.0, -150.0, -20.0, 0.0])
    for lo in (0, 3, 5):  # in three commits, as the runner's batches
        hi = {0: 3, 3: 5, 5: 8}[lo]
        rows = trace.reserve(hi - lo)
        rows[:] = 1.0
        rows[:, TRACE_KEYS.index("t_s")] = t[lo:hi]
        rows[:, TRACE_KEYS.index("rib_lift_mm")] = rib[lo:hi]
        rows[:, TRACE_KEYS.index("pressure_pa")] = np.nan
        trace.commit(hi - lo)
    table = metric_table(trace)
    assert table["rib_lift_mm"] == {"min": -150.0, "max": 2.0, "t_min_s": 2.0, "t_max_s": 0.5}
    assert "pressure_pa" not in table and set(table) == set(METRIC_KEYS) - {"pressure_pa"}


def test_provenance_in_the_summary_and_the_recording(tmp_path):
    """summary.json and the recording's metadata hold how the run was made: the resolved
    scene as TOML (loading back to the scene run), the overrides and removed terms as
    given, the step and integrator used, threads and machine."""
    out = tmp_path / "o"
    args = [
        "run",
        "membrane_demo",
        "--set",
        "forces.muscle.stiffness.breathing.peak=100",
        "--without",
        "damping",
        "--dt",
        "5e-4",
        "--duration",
        "0.05",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    p = _summary(out)["provenance"]
    assert PROVENANCE_KEYS <= set(p)
    assert p["command"] == "hybrid " + " ".join(args)
    assert p["overrides"] == ["forces.muscle.stiffness.breathing.peak=100"] and p["without"] == ["damping"]
    assert p["dt_s"] == 5e-4 and p["integrator"] == "symplectic_euler"
    assert isinstance(p["threads"]["numba_threads"], int) and p["threads"]["parallel_build"] is False
    assert p["machine"]["cpu_count"] >= 1 and p["version"]
    scene = scene_from_dict(tomllib.loads(p["scene_toml"]))
    expected = hybrid.load_scene(
        "membrane_demo", overrides=["forces.muscle.stiffness.breathing.peak=100"], without=["damping"]
    )
    assert scene == dataclasses.replace(expected, dt_s=5e-4)
    assert read(out / "run.mcap")["model"]["provenance"] == p


def test_the_same_command_twice_leaves_two_folders(tmp_path, monkeypatch, capsys):
    """Without --out a rerun goes to runs/NAME-2 and says so; the first run's folder is untouched."""
    monkeypatch.chdir(tmp_path)
    command = ["run", "membrane_demo", "--duration", "0.05", "--no-record"]
    assert main(command) == 0
    first = (tmp_path / "runs" / "membrane_demo" / "summary.json").read_bytes()
    capsys.readouterr()
    assert main(command) == 0
    err = capsys.readouterr().err
    assert "runs/membrane_demo holds an earlier run; this one goes to runs/membrane_demo-2" in err
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["membrane_demo", "membrane_demo-2"]
    assert (tmp_path / "runs" / "membrane_demo" / "summary.json").read_bytes() == first
    assert _summary(tmp_path / "runs" / "membrane_demo-2")["status"] == "ok"
    assert main([*command, "--overwrite"]) == 0  # asked: the first folder again
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["membrane_demo", "membrane_demo-2"]
    assert (tmp_path / "runs" / "membrane_demo" / "summary.json").read_bytes() != first
