"""A warm start spends its time on the run (issue 30, item 2): the command's process
leaves what it built to the operating system at its end (`hybrid.cli.main` freezes the
collector's objects: the interpreter's last collections freed them one by one, 0.3 s of
CPU after a warm run); `hybrid run` pauses the collector while it sets the run up and
resumes it, what setting up made frozen, before the run, then pauses it for the figure
(matplotlib's objects live to the end too); `main()` called by a program
leaves the collector alone. No test here times anything: each checks the mechanism."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
from pathlib import Path

from hybrid.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_main_called_by_a_program_leaves_the_collector_alone(capsys):
    before = gc.get_freeze_count()
    assert main(["run", "no_such_scene"]) == 2
    assert gc.get_freeze_count() == before
    assert "no_such_scene" in capsys.readouterr().err


def test_the_command_freezes_the_collector_at_its_end_and_still_says_its_error(tmp_path):
    code = (
        "import gc, sys; from hybrid.cli import main\n"
        "sys.argv = ['hybrid', 'run', 'no_such_scene']\n"
        "before = gc.get_freeze_count(); code = main()\n"
        "print(code, before == 0, gc.get_freeze_count() > 0)"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["2", "True", "True"]
    assert done.stderr.startswith("hybrid: error: ") and "no_such_scene" in done.stderr
    assert "Traceback" not in done.stderr


_WATCHED = """
import gc, json, sys
import hybrid.model, hybrid.run
from hybrid.cli import main

seen = []
compile_scene, run = hybrid.model.compile_scene, sys.modules["hybrid.run"].run


def watch(what, fn):
    def watched(*args, **kwargs):
        seen.append([what, gc.isenabled(), gc.get_freeze_count() > 0])
        return fn(*args, **kwargs)
    return watched


hybrid.model.compile_scene = watch("setup", compile_scene)
sys.modules["hybrid.run"].run = watch("run", run)
sys.modules["hybrid.run"].write_outputs = watch("outputs", sys.modules["hybrid.run"].write_outputs)
argv = ["run", "membrane_demo", "--duration", "0.002", "--no-record", "--out"]
main([*argv, sys.argv[1] + "/program"])  # called by a program
sys.argv = ["hybrid", *argv, sys.argv[1] + "/command"]
main()  # the command itself
print(json.dumps(seen))
"""


def test_the_run_command_sets_up_with_the_collector_paused_and_runs_with_it_on(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", _WATCHED, str(tmp_path)], capture_output=True, text=True, env=env, timeout=900
    )
    assert done.returncode == 0, done.stderr[-2000:]
    seen = json.loads(done.stdout.splitlines()[-1])
    assert seen == [
        ["setup", True, False],  # a program's main(): the collector as it was
        ["run", True, False],
        ["outputs", True, False],
        ["setup", False, False],  # the command: paused while it sets up
        ["run", True, True],  # on for the run, what setting up made frozen
        ["outputs", False, True],  # paused again for the figure
    ]
    for folder in ("program", "command"):
        assert (tmp_path / folder / "summary.json").is_file()
