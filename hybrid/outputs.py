"""Where a run writes and what: its folder (chosen so that no earlier run is
overwritten unless asked, locked while the run writes), `summary.json` and the
time-series plot named after the scene, with a panel for each part it has.

The folder rule (docs/getting-started.md, "Using it"): without --out, a run goes to runs/NAME, or
to the first of runs/NAME-2, runs/NAME-3, ... that holds no run when runs/NAME
holds one; an explicit --out that holds a run is refused. `overwrite=True`
(--overwrite) writes into the folder named whatever it holds.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from . import checks
from .errors import HybridError

__all__ = [
    "out_folder",
    "default_out",
    "LOCK_NAME",
    "FolderLock",
    "holds_run",
    "claim_folder",
    "write_summary",
    "write_outputs",
    "plot_name",
    "plot_trace",
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
        raise HybridError(
            f"--out: expected a folder that can be created and written, received {str(out)!r} ({exc.strerror or exc})"
        ) from None
    return out


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

    def __init__(self, folder: Path):
        import fcntl
        import os

        path = folder / LOCK_NAME
        self._fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(self._fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(self._fd)
            raise HybridError(
                f"--out: expected a folder no other run is writing, received {str(folder)!r}, "
                f"in use by hybrid run process {holder}; wait for it or choose another --out"
            ) from None
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)

    def release(self) -> None:
        import os

        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor releases the flock
            self._fd = None


def holds_run(folder: Path) -> str | None:
    """The file that shows a run was made (or is being made) in `folder`, else None."""
    for name in RUN_FILES:
        if (folder / name).exists():
            return name
    return None


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
        found = holds_run(out) if not overwrite else None
        if found is not None:
            lock.release()
            raise HybridError(
                f"--out: expected a folder that holds no earlier run, received {str(out)!r}, "
                f"which holds one ({found}); add --overwrite to replace it, or choose another --out"
            )
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
    """summary.json in out_dir, replaced whole (written aside, then renamed)."""
    tmp = out_dir / "summary.json.part"
    tmp.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    tmp.replace(out_dir / "summary.json")


def plot_name(scene_name: str) -> str:
    """The time-series plot's file name: the scene's name (a plain name, checked at load)."""
    return f"{scene_name}.png"


def write_outputs(result: dict, out_dir: Path, *, plot: bool = True) -> None:
    """Write summary.json (and the plot, `plot_name`) into out_dir."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_summary(result["summary"], out_dir)
    if plot:
        scene = result["summary"]["scene"]
        plot_trace(result["trace"], out_dir / plot_name(scene), title=scene)


#: a plot draws each series' lowest and highest value in this many runs of frames
PLOT_BINS = 2000

# the panels a plot may have, in order: (series, label, log scale)
_PANELS = (
    ("rib_lift_mm", "rib lift (mm)", False),
    ("apex_descent_mm", "apex descent (mm)", False),
    ("volume_rel_error", "volume error |V - V0| / V0", True),
    ("volume_rel_change", "volume change |V - V0| / V0", False),
    ("pressure_pa", "pressure (Pa)", False),
    ("muscle_n_per_m", "muscle stiffness (N/m)", False),
)


def plot_trace(trace, path: Path, *, title: str = "") -> None:
    """The time series of a run (`hybrid.run.Trace`), a panel each for what the scene
    has: rib lift, apex descent, the volume (its error under the exact constraint,
    on a log scale, else its change), pressure and muscle stiffness."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a = trace.envelope(PLOT_BINS)
    panels = [(key, label, log) for key, label, log in _PANELS if np.isfinite(a[key]).any()]
    if any(key == "volume_rel_error" for key, _, _ in panels):  # the change is the error then
        panels = [p for p in panels if p[0] != "volume_rel_change"]
    # fixed margins: tight_layout took half a second of every run
    height = 1.2 + 1.6 * len(panels)
    fig, axes = plt.subplots(
        len(panels),
        1,
        figsize=(7, height),
        sharex=True,
        squeeze=False,
        gridspec_kw=dict(left=0.13, right=0.97, top=1 - 0.45 / height, bottom=0.55 / height, hspace=0.15),
    )
    axes = axes[:, 0]
    for ax, (key, label, log) in zip(axes, panels):
        y = a[key]
        if log:
            ax.semilogy(a["t_s"], np.maximum(y, 1e-17))
        else:
            ax.plot(a["t_s"], y)
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title)
    fig.savefig(path, dpi=100)
    plt.close(fig)
