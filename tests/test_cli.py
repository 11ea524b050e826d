"""The command line: outputs, one-line errors with status 2, the benchmark's JSON, the recording."""

import json
import subprocess
import sys

import numpy as np
import pytest

from hybrid.cli import main
from hybrid.record import read


def run_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "hybrid", *args], capture_output=True, text=True, cwd=cwd, timeout=600)


def test_run_membrane_demo_writes_summary_and_plot(tmp_path):
    out = tmp_path / "demo"
    assert main(["run", "membrane_demo", "--duration", "4", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in (
        "scene",
        "steps",
        "dt",
        "duration_s",
        "wall_s",
        "us_per_step",
        "volume_rel_error_max",
        "volume_rel_change_max",
        "pressure_min_pa",
        "pressure_max_pa",
        "apex_descent_mm",
        "rest_return_mm",
        "metrics",
        "provenance",
    ):
        assert key in summary, key
    assert not [key for key in summary if "rib" in key]  # no ribs in this scene
    assert summary["steps"] == 4000
    assert summary["volume_rel_error_max"] <= 1e-12
    # the diaphragm contracts: the apex descends and the abdomen pressure rises
    assert summary["apex_descent_mm"] > 1.0
    assert summary["pressure_max_pa"] > 10.0
    assert (out / "membrane_demo.png").stat().st_size > 10_000


def test_set_overrides_a_python_scene_as_a_toml_one(tmp_path):
    out = tmp_path / "o"
    assert (
        main(
            [
                "run",
                "membrane_demo",
                "--set",
                "dt_s=2e-3",
                "--without",
                "muscle",
                "--duration",
                "0.1",
                "--no-record",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["dt"] == 2e-3 and summary["steps"] == 50


@pytest.mark.parametrize(
    "args, culprit",
    [
        (["run", "membrane_demo", "--dt", "-1"], "dt_s"),
        (["run", "membrane_demo", "--duration", "0"], "--duration"),
        (["run", "membrane_demo", "--without", "nosuchterm"], "nosuchterm"),
        (["run", "membrane_demo", "--bogus"], "--bogus"),
    ],
)
def test_bad_input_is_one_line_with_status_2(args, culprit, tmp_path):
    proc = run_cli(*args, "--out", str(tmp_path / "o"))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert culprit in lines[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    "command",
    [["run", "membrane_demo", "--duration", "0.01"], ["render", "membrane_demo"], ["study", "stability", "--small"]],
)
def test_an_output_folder_that_cannot_be_written_is_one_line_with_status_2(command, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    proc = run_cli(*command, "--out", str(blocker / "out"))  # a folder inside a file
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "--out: expected a folder that can be created and written" in lines[0]
    assert str(blocker / "out") in lines[0]


def test_diverging_run_keeps_what_it_recorded(tmp_path):
    # a step ten times the stability bound: diverges, exits 2, still writes the summary
    out = tmp_path / "div"
    code = main(["run", "membrane_demo", "--dt", "0.05", "--duration", "10", "--out", str(out)])
    assert code == 2
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    assert "diverged" in summary["error"]
    assert 0 < summary["steps"] < 200


def test_bench_quick_writes_json(tmp_path):
    path = tmp_path / "bench.json"
    assert main(["bench", "--quick", "--json", str(path)]) == 0
    data = json.loads(path.read_text())
    rows = data["membrane"]
    assert [r["nvert"] for r in rows] == [80, 642]
    for r in rows:
        assert r["us_per_step"] > 0
        assert r["ns_per_vertex_step"] == pytest.approx(r["us_per_step"] * 1e3 / r["nvert"])
        assert r["serial_us_per_step"] > 0 and r["parallel_us_per_step"] > 0  # both builds, every size
        assert r["default_build"] in ("serial", "parallel")
        assert r["default_serial_steps"] + r["default_parallel_steps"] > 0
    assert rows[0]["default_build"] == "serial" and rows[0]["default_parallel_steps"] == 0  # 80 points: never tried
    coupled = data["coupled"]
    # the median of per-repeat ratios lies between the extremes of the two medians' ratio
    assert 0.3 < coupled["ratio"] / (coupled["us_per_step"] / coupled["mj_step_us"]) < 3
    assert coupled["mj_step_us"] > 0


def test_study_subcommand_reaches_the_studies(tmp_path):
    proc = run_cli("study", "nosuchstudy", "--out", str(tmp_path / "s"))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "nosuchstudy" in lines[0], proc.stderr


def test_an_output_folder_that_cannot_be_written_is_refused_before_anything_compiles(tmp_path, monkeypatch, capsys):
    """On a first run the scene's helpers would compile (and the compile notice speak)
    before the folder was claimed: the folder is checked first, without creating it."""
    import hybrid.model

    def no_compile(scene):
        raise AssertionError("compile_scene called before --out was checked")

    monkeypatch.setattr(hybrid.model, "compile_scene", no_compile)
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main(["run", "membrane_demo", "--out", str(blocker / "out" / "deeper")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out: expected a folder that can be created and written" in err[0], err
    assert "Not a directory" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]  # nothing created


def test_a_file_system_error_during_a_run_is_one_line_with_status_74(tmp_path, monkeypatch, capsys):
    import errno
    import importlib

    runner = importlib.import_module("hybrid.run")  # the module (`hybrid.run` is its function)

    def full_disk(result, out, **_):
        raise OSError(errno.ENOSPC, "No space left on device", str(out / "summary.json"))

    monkeypatch.setattr(runner, "write_outputs", full_disk)
    # issue 31: a full disk is not bad input: EX_IOERR, not 2
    assert main(["run", "membrane_demo", "--duration", "0.01", "--out", str(tmp_path / "o")]) == 74
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"hybrid: error: cannot read or write {str(tmp_path / 'o' / 'summary.json')!r}: No space left on device"
    ]


def test_the_cli_run_that_diverges_still_writes_a_readable_recording(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "membrane_demo", "--dt", "0.006", "--duration", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "diverged" in err
    # said at the start, before the run: the step is above the stable-step estimate (0.0045 s)
    warning = next(line for line in err.splitlines() if "warning" in line)
    assert "dt_s = 0.006 s is above the stable-step estimate" in warning
    assert err.index(warning) < err.index("diverged")
    summary = json.loads((out / "summary.json").read_text())
    data = read(out / "run.mcap")
    t = data["membrane"]["t"]
    # frames every 2 steps (0.012 s) up to the last complete one before the failing step
    expected = np.arange(0, summary["steps"] + 1, 2) * 0.006
    np.testing.assert_allclose(t, expected, rtol=0, atol=1e-9)


def test_no_record_and_record_every(tmp_path, capsys):
    assert main(["run", "membrane_demo", "--duration", "0.1", "--out", str(tmp_path / "a"), "--no-record"]) == 0
    assert "warning" not in capsys.readouterr().err  # the scene's own step is below its stable one
    assert not (tmp_path / "a" / "run.mcap").exists()
    assert (
        main(["run", "membrane_demo", "--duration", "0.1", "--out", str(tmp_path / "b"), "--record-every", "0.05"]) == 0
    )
    np.testing.assert_allclose(read(tmp_path / "b" / "run.mcap")["/pressure"]["t"], [0.0, 0.05, 0.1], atol=1e-9)


def test_every_command_taking_a_scene_lists_every_packaged_scene_in_its_help(capsys):
    """Issue 29, item 6: `hybrid run --help` named two scenes where the unknown-name
    error names every one; the help now lists what the error lists, read off the package."""
    assert main(["run", "no_such_scene"]) == 2
    err = capsys.readouterr().err
    listed = err.rsplit("one of: ", 1)[1].strip().split(", ")
    assert len(listed) >= 4 and "myotorso_breathing" in listed  # a packaged scene file the help did not name
    for command in ("run", "view", "sweep", "render"):
        with pytest.raises(SystemExit) as exc:
            main([command, "--help"])
        assert exc.value.code == 0
        text = " ".join(capsys.readouterr().out.split())  # argparse wraps its lines
        missing = [name for name in listed if f" {name}," not in text and f" {name} " not in text]
        assert not missing, (command, missing)


def test_the_summary_says_the_meshs_point_count(tmp_path, capsys):
    """Issue 29, item 6: summary.json and the printed line name the mesh's point count,
    the recording's own (two meshes, so that the figure is read, not assumed)."""
    seen = []
    for level in ("0", "1"):
        out = tmp_path / level
        capsys.readouterr()
        argv = ["run", "membrane_demo", "--duration", "0.02", "--set", f"mesh.level={level}", "--out", str(out)]
        assert main(argv) == 0
        printed = capsys.readouterr().out
        points = read(out / "run.mcap")["membrane"]["pos"].shape[1]
        assert json.loads((out / "summary.json").read_text())["mesh_points"] == points
        assert printed.startswith(f"membrane_demo ({points}-point mesh): ")
        seen.append(points)
    assert seen[0] < seen[1]


@pytest.mark.parametrize(("users", "expected"), [(None, "disable"), ("glfw", "glfw")])
def test_a_command_leaves_mujocos_opengl_unloaded_unless_the_user_asks(users, expected):
    """Issue 30 (a warm start in about a second): MuJoCo's import loads its OpenGL binding
    (glfw, which starts a Python process to read its version) unless MUJOCO_GL says not to;
    no command but `hybrid view` draws with it. A MUJOCO_GL the user set is kept."""
    import os

    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    if users is not None:
        env["MUJOCO_GL"] = users
    code = (
        "import os, sys; from hybrid.cli import main; sys.argv = ['hybrid', 'inspect', 'breathing']; "
        "code = main(); print(code, os.environ.get('MUJOCO_GL'), 'mujoco' in sys.modules, 'glfw' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr
    status, gl, mujoco_loaded, glfw_loaded = out.stdout.split()[-4:]
    assert (status, gl, mujoco_loaded) == ("0", expected, "True")
    assert glfw_loaded == str(users is not None)  # glfw: MuJoCo loads its binding as asked
