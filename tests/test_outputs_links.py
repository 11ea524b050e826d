"""Output files are never written through a link someone left in the folder (issue 31,
item 1): every file `hybrid run`, `hybrid sweep` and `hybrid render` write, with a link
planted in its place, pointing at a file or dangling, leaves the link's target untouched;
a full disk is one line naming the path, no stray file, and not status 2."""

from __future__ import annotations

import errno
import importlib.util
import os
from pathlib import Path

import pytest

from hybrid.cli import main
from hybrid.outputs import LOCK_NAME, holds_run

VICTIM_TEXT = "the victim's own bytes\n"


def _plant(folder: Path, name: str, kind: str, tmp_path: Path) -> Path:
    """A link `folder/name` to a victim outside the folder: an existing file, or none (dangling)."""
    folder.mkdir(parents=True, exist_ok=True)
    victim = tmp_path / f"victim-{name.strip('.')}-{kind}"
    if kind == "file":
        victim.write_text(VICTIM_TEXT)
    os.symlink(victim, folder / name)
    return victim


def _untouched(victim: Path, kind: str) -> None:
    if kind == "file":
        assert victim.read_text() == VICTIM_TEXT
    else:
        assert not os.path.lexists(victim), f"{victim} was created through a dangling link"


RUN_FILES = ["summary.json", "summary.json.part", LOCK_NAME, "membrane_demo.png", "run.mcap"]


@pytest.mark.parametrize("kind", ["file", "dangling"])
def test_no_run_output_is_written_through_a_link(tmp_path, kind, capsys):
    for name in RUN_FILES:
        out = tmp_path / f"out-{name.strip('.')}"
        victim = _plant(out, name, kind, tmp_path)
        argv = ["run", "membrane_demo", "--duration", "0.02", "--out", str(out)]
        status = main(argv)
        if holds_run(out) is not None and status == 2:  # a link named like a run's file is a run's: refused
            assert "holds no earlier run" in capsys.readouterr().err
            _untouched(victim, kind)
            status = main([*argv, "--overwrite"])
        assert status == 0, (name, capsys.readouterr().err)
        _untouched(victim, kind)
        assert (out / "summary.json").is_file() and not (out / "summary.json").is_symlink()


def test_a_dangling_recording_link_makes_the_folder_hold_a_run(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    os.symlink(tmp_path / "nowhere", out / "run.mcap")
    assert holds_run(out) == "run.mcap"


SWEEP_FILES = ["sweep.jsonl", "sweep.csv", "sweep.png", "sweep.json", LOCK_NAME]


@pytest.mark.parametrize("kind", ["file", "dangling"])
def test_no_sweep_output_is_written_through_a_link(tmp_path, kind, capsys):
    for name in SWEEP_FILES:
        out = tmp_path / f"sw-{name.strip('.')}"
        victim = _plant(out, name, kind, tmp_path)
        argv = ["sweep", "membrane_demo", "--set", "dt_s=1e-3,5e-4", "--duration", "0.01", "--workers", "1"]
        assert main([*argv, "--out", str(out)]) == 0, (name, capsys.readouterr().err)
        _untouched(victim, kind)
        assert (out / "sweep.csv").is_file() and not (out / name).is_symlink()


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "run"
    assert main(["run", "membrane_demo", "--duration", "0.3", "--out", str(out)]) == 0
    return out / "run.mcap"


@pytest.mark.parametrize("kind", ["file", "dangling"])
def test_no_render_output_is_written_through_a_link(recording, tmp_path, kind, capsys):
    names = ["figure4.png"]
    video = importlib.util.find_spec("imageio_ffmpeg") is not None
    if video:
        names.append("run.mp4")
    for name in names:
        out = tmp_path / f"fig-{name}"
        victim = _plant(out, name, kind, tmp_path)
        assert main(["render", str(recording), "--out", str(out), *(["--video"] if video else [])]) == 0, (
            capsys.readouterr().err
        )
        _untouched(victim, kind)
        assert (out / name).is_file() and not (out / name).is_symlink()


def test_a_full_disk_is_one_line_naming_the_path_no_stray_file_and_not_status_2(tmp_path, monkeypatch, capsys):
    """A simulated ENOSPC while the summary is written: status 74 (EX_IOERR), one line
    naming summary.json, and no half-written file left beside it."""
    import hybrid.outputs as outputs

    class Full:
        """A file whose writes find the disk full."""

        def __init__(self, f):
            self.f = f

        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    def full_open(path, mode="r", **kwargs):
        f = open(path, mode, **kwargs)
        return Full(f) if "summary.json" in str(path) else f

    monkeypatch.setattr(outputs, "open", full_open, raising=False)
    out = tmp_path / "o"
    status = main(["run", "membrane_demo", "--duration", "0.02", "--no-record", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == outputs.EXIT_IO != 2
    assert len(err) == 1 and str(out / "summary.json") in err[0] and "No space left" in err[0], err
    assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]


def test_a_full_disk_under_the_recording_names_the_recording():
    """/dev/full refuses every write with ENOSPC: the recorder's error names its file."""
    import hybrid
    from hybrid.outputs import OutputError
    from hybrid.record import Recorder

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    sim = hybrid.load("membrane_demo")
    with pytest.raises(OutputError) as info:
        with Recorder("/dev/full", sim) as rec:
            hybrid.run(sim, 0.2, observers=[rec])
    assert str(info.value) == "cannot write '/dev/full': No space left on device"
    assert info.value.errno == errno.ENOSPC
