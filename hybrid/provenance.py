"""How a run was made, as plain data: the "provenance" table of `summary.json` and
of the recording's metadata (docs/outputs.md).

`run_provenance(sim, command=..., overrides=..., without=...)` gives the package
version and git commit, the command line, the fully resolved scene as TOML text,
the overrides and removed terms, the integrator and step actually used, the
threads numba runs and whether the step runs its parallel build, and the machine.
"""

from __future__ import annotations

import functools
import os
import platform
import shlex
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

__all__ = ["run_provenance", "package_version", "git_commit"]

_PACKAGE_ROOT = Path(__file__).resolve().parent


@functools.lru_cache(maxsize=1)
def package_version() -> str | None:
    """The installed distribution's version, read from hybrid.__version__ when it was
    installed (None when the source is not installed). Not imported from the package
    itself: the observers sit below the public API."""
    from importlib import metadata

    try:
        return metadata.version("hybrid-trunk")
    except metadata.PackageNotFoundError:
        return None


@functools.lru_cache(maxsize=1)
def git_commit(root: Path = _PACKAGE_ROOT.parent) -> dict:
    """{"commit": the checkout's HEAD, "dirty": whether tracked files differ from it}
    when the package sits in a git checkout, else both None. Asked once a process."""
    if not (root / ".git").exists():  # a folder (a clone) or a file (a worktree)
        return {"commit": None, "dirty": None}

    def git(*args) -> str:
        return subprocess.run(
            ["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10, check=True
        ).stdout.strip()

    try:
        commit = git("rev-parse", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
    except (OSError, subprocess.SubprocessError):  # no git program, or not a repository after all
        return {"commit": None, "dirty": None}
    return {"commit": commit, "dirty": dirty}


def _scene_toml(scene) -> tuple[str | None, str | None]:
    """(the scene as TOML text, None), or (None, why not) for what TOML cannot hold."""
    from .errors import HybridError
    from .scenefile import scene_to_toml

    try:
        return scene_to_toml(scene), None
    except HybridError as exc:
        return None, " ".join(str(exc).split())


def _usable_cpus() -> int | None:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return None


def run_provenance(sim, *, command: list[str] | None = None, overrides=None, without=None) -> dict:
    """The provenance table of a run of `sim` (a `Simulation`). `command`: the command
    line's words (default: this process's `sys.argv`); `overrides` ("KEY=VALUE") and
    `without` (term names): as given to `hybrid run` (None: not known, e.g. a scene
    built in Python; the resolved scene in "scene_toml" holds them anyway)."""
    from .kernel import numba_info
    from .scene import INTEGRATORS

    model = sim.model
    info = numba_info()
    toml, why = _scene_toml(model.scene)
    git = git_commit()
    words = list(sys.argv) if command is None else list(command)
    table = {
        "version": package_version(),
        "git_commit": git["commit"],
        "git_dirty": git["dirty"],
        "command": shlex.join(words),
        "started_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "scene": model.scene.name,
        "scene_toml": toml,
        "overrides": None if overrides is None else list(overrides),
        "without": None if without is None else list(without),
        "integrator": INTEGRATORS[model.arrays.integrator],
        "dt_s": model.dt_s,
        "threads": {"numba_threads": info["numba_threads"], "parallel_build": bool(model.arrays.parallel)},
        "machine": {
            "cpu_count": os.cpu_count(),
            "cpus_usable": _usable_cpus(),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "numba": info["numba"],
        },
    }
    if why is not None:
        table["scene_toml_error"] = why
    return table
