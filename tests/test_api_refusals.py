"""Wrong calls of the Python API are one-line `hybrid` errors naming the argument, what
was expected and what was received (issue 31, items 8 and 10); numpy scalars are
numbers; the command line's --duration replaces the scene's before it is checked; a
signal after the last step leaves a run "ok" with status 0."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import hybrid
from hybrid.cli import main
from hybrid.errors import HybridError

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def sim():
    return hybrid.load("membrane_demo")


def _refused(call, *named) -> str:
    with pytest.raises(HybridError) as info:
        call()
    text = str(info.value)
    assert "\n" not in text, text
    for piece in named:
        assert piece in text, (piece, text)
    return text


def test_simulation_of_a_scene_names_the_model_argument():
    _refused(lambda: hybrid.Simulation(hybrid.load_scene("membrane_demo")), "model", "hybrid.Model", "Scene")


def test_run_of_a_name_names_the_sim_argument():
    _refused(lambda: hybrid.run("membrane_demo", 0.1), "sim", "hybrid.Simulation", "'membrane_demo'")


@pytest.mark.parametrize("value", [0, -1, float("nan"), float("inf"), "0.01", True])
def test_run_refuses_a_frame_interval_that_is_no_time(sim, value):
    _refused(lambda: hybrid.run(sim, 0.01, frame_dt_s=value), "frame_dt_s", "finite time > 0 s", repr(value))


def test_run_refuses_one_observer_for_a_list(sim):
    _refused(lambda: hybrid.run(sim, 0.01, observers="abc"), "observers", "list")


def test_step_of_more_than_int64_steps_is_refused_not_a_typing_dump(sim):
    _refused(lambda: sim.step(2**70), "n", "2^63", str(2**70))


def test_a_term_where_a_tuple_goes_is_refused():
    _refused(lambda: hybrid.Scene(forces=hybrid.Gravity()), "Scene.forces", "tuple", "Gravity")


def test_a_list_of_regions_is_refused():
    _refused(lambda: hybrid.Scene(regions=["top"]), "Scene.regions", "dict", "list")


@pytest.mark.parametrize("kw", ["overrides", "without"])
def test_a_string_where_a_list_goes_is_refused_not_split(kw):
    _refused(lambda: hybrid.load_scene("membrane_demo", **{kw: "dt_s=2e-3"}), kw, "list", "'dt_s=2e-3'")


def test_set_state_with_strings_says_what_they_are(sim):
    text = _refused(lambda: sim.set_state(vert_pos=np.full((sim.model.nvert, 3), "a")), "vert_pos", "<U1")
    assert text.count(f"({sim.model.nvert}, 3)") == 2  # expected, and received of another kind


def test_a_numpy_scalar_step_is_a_number():
    scene = dataclasses.replace(hybrid.load_scene("membrane_demo"), dt_s=np.float32(1e-3))
    assert hybrid.compile_scene(scene).dt_s == float(np.float32(1e-3))


def test_a_scalar_function_schedule_returning_a_vector_is_refused():
    scene = hybrid.load_scene("membrane_demo")
    forces = tuple(
        dataclasses.replace(f, stiffness=hybrid.Function(lambda t: [60.0, 0.0, 0.0]))
        if isinstance(f, hybrid.Muscle)
        else f
        for f in scene.forces
    )
    _refused(
        lambda: hybrid.compile_scene(dataclasses.replace(scene, forces=forces)), "stiffness", "a number", "3 values"
    )


def test_duration_flag_replaces_the_scenes_own_before_it_is_checked(tmp_path, capsys):
    out = tmp_path / "o"
    argv = ["run", "membrane_demo", "--duration", "0.05", "--set", "duration_s=0.001", "--dt", "0.002"]
    assert main([*argv, "--no-record", "--out", str(out)]) == 0, capsys.readouterr().err
    assert json.loads((out / "summary.json").read_text())["steps"] == 25


def test_a_signal_after_the_last_step_leaves_the_run_ok_and_status_0(tmp_path):
    """SIGINT sent while the finished run's line is printed (after its handlers are
    gone): the summary says "ok", and so does the exit status."""
    out = tmp_path / "o"
    code = textwrap.dedent(
        f"""
        import os, signal, sys
        import hybrid.cli as cli
        line = cli._metrics_line
        def late(s):
            os.kill(os.getpid(), signal.SIGINT)
            return line(s)
        cli._metrics_line = late
        sys.argv = ["hybrid", "run", "membrane_demo", "--duration", "0.02", "--no-record", "--out", {str(out)!r}]
        sys.exit(cli.main())
        """
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "ok"
    assert proc.returncode == 0, (proc.returncode, proc.stderr)
    assert proc.returncode != 128 + signal.SIGINT


# ------------------------------------------------------------------ advice that works when followed


def test_a_mesh_in_millimetres_is_named_in_the_advice_and_following_it_runs():
    import helpers  # noqa: F401 - tests/ on the path
    from test_implicit import trunk

    def scaled(k: float):
        sc = trunk()
        regions = {
            "pelvis": hybrid.HalfSpace((0, 0, -0.09 * k), (0, 0, -1)),
            "dome": hybrid.HalfSpace((0, 0, 0.05 * k), (0, 0, 1)),
        }
        forces = tuple(
            dataclasses.replace(f, toward_m=(0, 0, 0.12 * k)) if isinstance(f, hybrid.MuscleFibres) else f
            for f in sc.forces
        )
        mesh = dataclasses.replace(sc.mesh, radius_m=0.12 * k)
        return dataclasses.replace(sc, mesh=mesh, regions=regions, forces=forces)

    # radius 120: millimetres taken for metres, refused when the scene compiles, the advice in its line
    with pytest.raises(hybrid.SceneError) as info:
        hybrid.compile_scene(scaled(1000.0))
    msg = str(info.value)
    assert "240 m across" in msg and "radius_m = 0.12" in msg and "\n" not in msg
    followed = hybrid.Simulation(hybrid.compile_scene(scaled(1.0)))
    followed.step(1000)  # in metres, the same step runs


def test_set_state_refuses_speeds_the_runaway_guard_stops_at_once(sim):
    vel = np.full((sim.model.nvert, 3), 1e200)
    _refused(lambda: sim.set_state(vert_vel=vel), "vert_vel", "max_speed_m_s", "1.73e+200")


def test_a_sweeps_unknown_metric_is_refused_before_any_run(tmp_path, capsys):
    out = tmp_path / "sw"
    argv = ["sweep", "membrane_demo", "--set", "dt_s=1e-3,5e-4", "--duration", "100", "--metric", "nonsense"]
    assert main([*argv, "--workers", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--metric 'nonsense'" in err[0] and "apex_descent_mm" in err[0], err
    assert not out.exists()  # refused before the folder, and before 2 runs of 100 s
