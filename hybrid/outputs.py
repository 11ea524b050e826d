"""Where a run writes and what: its folder (chosen so that no earlier run is
overwritten unless asked, locked while the run writes), `summary.json` and the
time-series plot named after the scene, with a panel for each part it has.

The folder rule (docs/getting-started.md, "Using it"): without --out, a run goes to runs/NAME, or
to the first of runs/NAME-2, runs/NAME-3, ... that holds no run when runs/NAME
holds one; an explicit --out that holds a run is refused. `overwrite=True`
(--overwrite) writes into the folder named whatever it holds.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from . import checks
from .errors import HybridError

__all__ = [
    "out_folder",
    "check_out_folder",
    "replaced",
    "replacing",
    "write_text",
    "save_figure",
    "create_new",
    "open_append",
    "OutputError",
    "default_out",
    "LOCK_NAME",
    "FolderLock",
    "holds_run",
    "run_status",
    "recording_path",
    "claim_folder",
    "write_summary",
    "write_outputs",
    "plot_name",
    "plot_trace",
    "figure_series",
    "trace_figure",
    "PLOT_BINS",
]


def out_folder(out: Path) -> Path:
    """The output folder `out`, created now: a folder that cannot be written fails
    before the run (a HybridError naming --out)."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise _unwritable(out, exc.strerror or str(exc)) from None
    return out


def _unwritable(out: Path, reason: str) -> HybridError:
    return HybridError(f"--out: expected a folder that can be created and written, received {str(out)!r} ({reason})")


def check_out_folder(out: Path, *, refuse_a_run: bool = False) -> None:
    """Refuse, without creating anything, an output folder that cannot be created or
    written: the nearest part of `out` that exists must be a folder this process may
    write into; with `refuse_a_run` (an explicit --out without --overwrite), one that holds
    a run. `hybrid run` asks before it builds anything, so that a bad --out is refused at
    once, not after the scene's kernels compile; `claim_folder` checks again when the run
    claims the folder. The same messages as out_folder's and claim_folder's."""
    if refuse_a_run and holds_run(out) is not None:
        if _lock_free(out) is False:  # a run writing there: named as claim_folder names it
            FolderLock(out).release()
        raise _holds_run_error(out)
    probe = out.absolute()
    while not os.path.lexists(probe) and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        reason = "Not a directory"
    elif not os.access(probe, os.W_OK | os.X_OK):
        reason = "Permission denied"
    else:
        return
    raise _unwritable(out, reason)


def _holds_run_error(out: Path) -> HybridError:
    found = holds_run(out)
    earlier = run_status(out)
    if earlier is not None and earlier.get("died"):
        found = f"{found}, interrupted: {earlier['died']}"
    return HybridError(
        f"--out: expected a folder that holds no earlier run, received {str(out)!r}, "
        f"which holds one ({found}); add --overwrite to replace it, or choose another --out"
    )


class OutputError(HybridError, OSError):
    """An output file could not be written (a full disk, a folder that refuses):
    not the input's fault, so the command line exits `EXIT_IO`, not 2."""

    def __init__(self, path: str, reason: str, code: int = 0):
        OSError.__init__(self, code, reason, path)
        self.args = (f"cannot write {path!r}: {reason}",)

    def __str__(self) -> str:
        return self.args[0]


def _output_error(path, exc: OSError) -> OutputError:
    return OutputError(str(path), exc.strerror or str(exc), exc.errno or 0)


#: the command line's status when an output cannot be written (sysexits' EX_IOERR)
EXIT_IO = 74

# Output files are never followed through a link someone left in the folder: a file
# is written aside under a fresh name (created exclusively) and renamed over the
# name it goes to, or created after whatever held its name is removed; rename and
# unlink act on a link itself, never on its target.
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


@contextlib.contextmanager
def replacing(path):
    """A fresh file's path beside `path` (same suffix), renamed to `path` when the
    block ends without an exception, removed otherwise: `path` is replaced whole,
    whatever was there (a link stays untouched where it points). An OSError is
    an `OutputError` naming `path`."""
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=f".part{path.suffix}")
        os.close(fd)
    except OSError as exc:
        raise _output_error(path, exc) from None
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, HybridError):
            raise _output_error(path, exc) from None
        raise


@contextlib.contextmanager
def replaced(path, mode: str = "w", **kwargs):
    """`replacing(path)` as an open file (`mode` "w" or "wb", open()'s keywords)."""
    with replacing(path) as tmp:
        try:
            with open(tmp, mode, **kwargs) as f:
                yield f
        except OSError as exc:
            if isinstance(exc, HybridError):
                raise
            raise _output_error(path, exc) from None


def write_text(path, text: str) -> None:
    """`text` into `path` (UTF-8), replaced whole, never through a link."""
    with replaced(path, "w", encoding="utf-8") as f:
        f.write(text)


def save_figure(fig, path, **kwargs) -> None:
    """A matplotlib figure into `path` as PNG, replaced whole, never through a link."""
    with replaced(path, "wb") as f:
        fig.savefig(f, format="png", **kwargs)


def _drop(path: Path) -> None:
    """Remove what holds `path`'s name: a link goes, its target stays untouched."""
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    except OSError as exc:
        raise _output_error(path, exc) from None


def create_new(path, mode: str = "wb"):
    """`path` created anew for writing (an earlier file or link of that name removed
    first, the new one created exclusively, never through a link): an open file. A
    device or a pipe of that name (/dev/null) is opened as it is, never removed."""
    import stat

    path = Path(path)
    try:
        kind = os.lstat(path).st_mode
    except FileNotFoundError:
        kind = None
    except OSError as exc:
        raise _output_error(path, exc) from None
    if kind is not None and not (stat.S_ISLNK(kind) or stat.S_ISREG(kind)):  # a device (/dev/null), a pipe
        try:
            return os.fdopen(os.open(path, os.O_WRONLY | _NOFOLLOW), mode)
        except OSError as exc:
            raise _output_error(path, exc) from None
    if kind is not None:  # a file or a link: removed (a link's target untouched), never written through
        _drop(path)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW, 0o644)
    except OSError as exc:
        raise _output_error(path, exc) from None
    return os.fdopen(fd, mode)


def open_append(path, mode: str = "a", **kwargs):
    """`path` opened to append, created if absent; a link of that name is removed
    first (its target untouched) and the file opened without following links."""
    path = Path(path)
    if path.is_symlink():
        _drop(path)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | _NOFOLLOW, 0o644)
    except OSError as exc:
        raise _output_error(path, exc) from None
    return os.fdopen(fd, mode, **kwargs)


def read_own(path, default=None) -> str | None:
    """The text of an output file of ours, or `default` when there is none or a link
    holds its name (a link is never read as ours)."""
    try:
        fd = os.open(path, os.O_RDONLY | _NOFOLLOW)
    except OSError:
        return default
    with os.fdopen(fd, encoding="utf-8", errors="replace") as f:
        return f.read()


def default_out(scene_name: str) -> Path:
    """runs/<scene name>, the folder of a run without --out. The name is a name:
    one that could lead elsewhere (a path separator, '..', a NUL) or none at all
    is refused, so that only --out chooses where a run writes."""
    checks.plain_name("scene name", scene_name)
    return Path("runs") / scene_name


#: the lock file a run holds in its output folder, with the process id inside
LOCK_NAME = ".hybrid-run.lock"
#: what a folder holds once a run has started there (the lock file alone is no run:
#: it stays after a run refused before it started)
RUN_FILES = ("summary.json", "run.mcap")


class FolderLock:
    """An exclusive lock on an output folder (fcntl.flock on `LOCK_NAME` inside it)
    for as long as a run writes there: a second run into the same folder is refused
    with a HybridError naming the first's process id. The lock goes with the process,
    however it ends; the file stays."""

    def __init__(self, folder: Path, *, what: str = "run"):
        import fcntl

        path = folder / LOCK_NAME
        if path.is_symlink():  # never followed: the link goes, its target stays
            _drop(path)
        try:
            self._fd = os.open(path, os.O_RDWR | os.O_CREAT | _NOFOLLOW, 0o644)
        except OSError as exc:
            raise _output_error(path, exc) from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(self._fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(self._fd)
            raise HybridError(
                f"--out: expected a folder no other run is writing, received {str(folder)!r}, "
                f"in use by hybrid {what} process {holder}; wait for it or choose another --out"
            ) from None
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor releases the flock
            self._fd = None


def holds_run(folder: Path) -> str | None:
    """The file that shows a run was made (or is being made) in `folder`, else None."""
    for name in RUN_FILES:
        if os.path.lexists(folder / name):  # a link, even dangling, counts: it is never followed
            return name
    return None


def _lock_free(folder: Path) -> bool | None:
    """Whether no process holds the folder's lock (None: no lock file of ours there)."""
    import fcntl

    try:
        fd = os.open(Path(folder) / LOCK_NAME, os.O_RDONLY | _NOFOLLOW)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    finally:
        os.close(fd)  # a lock taken here goes with the descriptor
    return True


def _alive(pid) -> bool:
    if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def run_status(folder) -> dict | None:
    """The summary of the run in `folder` (None without one), as it stands: a summary
    that says "running" while the folder's lock is free (or, without a lock file, its
    process "pid" is gone) is of a run that died (killed, a full disk): its "status" is
    then "interrupted" and "died" says why."""
    text = read_own(Path(folder) / "summary.json")
    if text is None:
        return None
    try:
        summary = json.loads(text)
    except ValueError:
        return None
    if not isinstance(summary, dict) or summary.get("status") != "running":
        return summary
    free = _lock_free(folder)
    pid = summary.get("pid")
    if free or (free is None and not _alive(pid)):
        summary["status"] = "interrupted"
        summary["died"] = f"its process {pid} ended without finishing summary.json (killed, or a full disk)"
    return summary


#: bytes of an MCAP file's magic: a file of no more holds no record
MCAP_MAGIC_BYTES = 8


def recording_path(path, *, strict: bool = True) -> Path:
    """`path` as `hybrid.read` takes it, checked: a str or path naming an existing file
    (a HybridError naming what was received otherwise); with `strict`, a file of at
    most the MCAP magic's 8 bytes (a run killed before its first record) is refused.
    A recording whose run died (`run_status`) is read with a RecordingWarning saying so."""
    import warnings

    from .record.mcap_reader import RecordingError, RecordingWarning

    if not isinstance(path, (str, os.PathLike)) or isinstance(path, bytes):
        raise HybridError(f"path: expected a path to a .mcap recording, received {path!r} ({type(path).__name__})")
    path = Path(path)
    if not path.exists():
        raise HybridError(f"path: expected an existing .mcap recording, received {str(path)!r}, which does not exist")
    if not path.is_file():
        raise HybridError(f"path: expected a .mcap recording file, received {str(path)!r}, which is a folder")
    size = path.stat().st_size
    if strict and size <= MCAP_MAGIC_BYTES:
        raise RecordingError(
            f"{str(path)!r}: expected an MCAP recording, received a file of {size} bytes, which holds no "
            f"record (a run killed before it wrote any); strict=False reads it as empty"
        )
    run = run_status(path.parent) if path.name == "run.mcap" else None
    if run is not None and run.get("died"):
        warnings.warn(
            f"recording {str(path)!r}: the run was interrupted: {run['died']}", RecordingWarning, stacklevel=3
        )
    return path


#: runs/NAME-2 up to this suffix are tried before a default folder is refused
MAX_SUFFIX = 10_000


def claim_folder(out: Path, *, explicit: bool, overwrite: bool = False) -> tuple[Path, FolderLock]:
    """The folder a run writes into, created and locked: (folder, lock).

    `explicit` (--out DIR): DIR itself; one another run is writing is refused
    (naming its process), one that holds a finished run too unless `overwrite`.
    Else (runs/NAME): runs/NAME unless it holds a run, then the first of runs/NAME-2,
    -3, ... that holds none (`overwrite`: runs/NAME whatever it holds). A folder is
    taken only once locked and seen free, so two runs started at once get two."""
    if explicit or overwrite:
        created = not out.exists()
        out_folder(out)
        try:
            lock = FolderLock(out)
        except HybridError:
            if created:
                try:
                    out.rmdir()
                except OSError:  # the other run has written into it meanwhile
                    pass
            raise
        if not overwrite and holds_run(out) is not None:
            lock.release()
            raise _holds_run_error(out)
        return out, lock
    for k in range(1, MAX_SUFFIX + 1):
        folder = out if k == 1 else out.with_name(f"{out.name}-{k}")
        if holds_run(folder) is not None:
            continue
        out_folder(folder)
        try:
            lock = FolderLock(folder)
        except HybridError:  # another run took it meanwhile
            continue
        if holds_run(folder) is not None:  # a run finished there meanwhile
            lock.release()
            continue
        return folder, lock
    raise HybridError(
        f"--out: {str(out)!r} and its {MAX_SUFFIX - 1} numbered siblings all hold runs; choose --out or --overwrite"
    )


def write_summary(summary: dict, out_dir: Path) -> None:
    """summary.json in out_dir, replaced whole (written aside, then renamed; never
    through a link)."""
    write_text(out_dir / "summary.json", json.dumps(summary, indent=2, allow_nan=False) + "\n")


def plot_name(scene_name: str) -> str:
    """The time-series plot's file name: the scene's name (a plain name, checked at load)."""
    return f"{scene_name}.png"


def write_outputs(result: dict, out_dir: Path, *, plot: bool = True, drawer=None) -> None:
    """Write summary.json (and the plot, `plot_name`) into out_dir. `drawer`: as `plot_trace`."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_summary(result["summary"], out_dir)
    if plot:
        scene = result["summary"]["scene"]
        plot_trace(result["trace"], out_dir / plot_name(scene), title=scene, drawer=drawer)


#: a plot draws each series' lowest and highest value in this many runs of frames
PLOT_BINS = 2000
#: points at most of a diagram's loop (every k-th frame: x and y of the same frames)
DIAGRAM_POINTS = 4000


def _diagrams(trace) -> dict | None:
    """The Campbell and Konno-Mead diagrams' series (every k-th frame, the same frames
    for x and y), or None for a trace without lungs."""
    keys = (
        "lung_volume_change_l",
        "pleural_pressure_cmh2o",
        "rib_cage_pulmonary_volume_change_l",
        "rib_cage_abdominal_volume_change_l",
        "abdomen_volume_change_l",
    )
    n = len(trace)
    if not n or "resting_recoil_cmh2o" not in getattr(trace, "about", {}):
        return None
    d = trace.columns(keys, every=-(-n // DIAGRAM_POINTS))
    return d if np.isfinite(d["lung_volume_change_l"]).any() else None


def figure_series(trace) -> dict:
    """What the run's figure draws (`hybrid.pictures.run_figure.draw`), arrays and names
    only: the envelope of each series drawn ("t_s" and a key each), "panels" (series,
    label, log scale) for what the scene has, "about" and "diagrams" (or None)."""
    from .pictures.run_figure import LUNG_PRESSURES, PANELS

    a = trace.envelope(PLOT_BINS)
    about = getattr(trace, "about", {})
    panels: list = [(key, label, log) for key, label, log in PANELS if np.isfinite(a[key]).any()]
    if any(key == "volume_rel_error" for key, _, _ in panels):  # the change is the error then
        panels = [p for p in panels if p[0] != "volume_rel_change"]
    panels = [
        (k, about.get("muscle") or lab, log) if k == "muscle_n_per_m" else (k, lab, log) for k, lab, log in panels
    ]
    if np.isfinite(a[LUNG_PRESSURES[0][0]]).any():
        panels.append((LUNG_PRESSURES, "pressure change\n(cmH2O)", False))
    drawn = {"t_s"} | {name for k, _, _ in panels for name in ([s for s, _ in k] if isinstance(k, tuple) else [k])}
    return {
        **{k: np.asarray(a[k]) for k in drawn},
        "panels": panels,
        "about": dict(about),
        "diagrams": _diagrams(trace),
    }


def plot_trace(trace, path: Path, *, title: str = "", drawer=None) -> None:
    """`trace_figure(trace, title)` into `path` as PNG, replaced whole. `drawer`: a
    `hybrid.pictures.run_figure.FigureProcess` that draws it in a process of its own;
    drawn here without one, or when that process failed."""
    from .pictures.run_figure import png_bytes

    series = figure_series(trace)
    png = drawer.png(series, title) if drawer is not None else None
    if png is None:
        png = png_bytes(series, title=title)
    with replaced(path, "wb") as f:
        f.write(png)


def trace_figure(trace, *, title: str = ""):
    """The run's figure (a matplotlib figure; the caller closes it): the time series
    of a run (`hybrid.run.Trace`), a panel each for what the scene has: rib lift, apex
    descent, the volume (its error under the exact constraint, on a log scale, else its
    change), the pressure inside and the muscle's schedule
    (stiffness or fibre tension, as `trace.about["muscle"]` says); with lungs, the lung
    volume, the flow, the pleural pressure and, in one panel, the alveolar pressure and
    the transdiaphragmatic pressure's change, and under them a Campbell diagram and, with a region named "diaphragm", a
    Konno-Mead diagram (docs/outputs.md). Drawn by `hybrid.pictures.run_figure.draw`."""
    from .pictures.run_figure import draw

    return draw(figure_series(trace), title=title)
