"""Running the studies, the benchmark and the gallery's scripts again, and keeping what
they made (JSON, figures) with how it was made."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .gallery import script_names
from .paths import DATA, DOCS, GALLERY_FIGURES, SCRIPTS
from .study_pages import STUDIES

__all__ = ["rerun", "rerun_gallery"]


def _machine() -> dict:
    import os
    import platform

    return {
        "platform": platform.platform(terse=True),
        "cpu_count": os.cpu_count(),
        "load_1min": round(os.getloadavg()[0], 2),
        "python": platform.python_version(),
    }


def _made(command: list[str], size: str) -> dict:
    from datetime import UTC, datetime

    from .. import __version__
    from ..provenance import git_commit

    return {
        "command": " ".join(command),
        "date_utc": datetime.now(UTC).strftime("%Y-%m-%d %H:%M"),
        "version": __version__,
        "git_commit": git_commit()["commit"],
        "size": size,
        "machine": _machine(),
    }


def rerun(names=None, *, full: bool = False, data: Path = DATA) -> None:
    """Run the studies (`names`, by default all) and store {"made_by", "result"} in
    data/NAME.json, their figures in docs/figures/studies/."""
    import shutil
    import subprocess
    import tempfile

    figures = DOCS / "figures" / "studies"
    figures.mkdir(parents=True, exist_ok=True)
    data.mkdir(parents=True, exist_ok=True)
    for name in names or STUDIES:
        study = STUDIES[name]
        with tempfile.TemporaryDirectory() as tmp:
            target = Path(tmp) / (study.json_name if study.command[0] == "bench" else "out")
            size_flag = [] if full else (["--quick"] if study.command[0] == "bench" else ["--small"])
            args = [*study.command[:-1], *size_flag, study.command[-1]]
            shown = ["hybrid", *args, "DIR" if study.command[0] != "bench" else study.json_name]
            print("running", " ".join(shown), flush=True)
            subprocess.run([sys.executable, "-m", "hybrid", *args, str(target)], check=True)
            folder = target if target.is_dir() else target.parent
            result = json.loads((folder / (study.written or study.json_name)).read_text(encoding="utf-8"))
            stored = {"made_by": _made(shown, "full" if full else "small"), "result": result}
            (data / study.json_name).write_text(json.dumps(stored, indent=1) + "\n", encoding="utf-8")
            for fig in study.figures:
                shutil.copy2(folder / fig, figures / fig)


def rerun_gallery(names=None, *, quick: bool = False) -> None:
    """Run the scripts (`names`, by default all) and keep each one's figure in
    docs/figures/gallery/NAME.png, with the command in made_by.json."""
    import shutil
    import subprocess
    import tempfile

    GALLERY_FIGURES.mkdir(parents=True, exist_ok=True)
    record = GALLERY_FIGURES / "made_by.json"
    made = json.loads(record.read_text(encoding="utf-8")) if record.is_file() else {}
    for name in names or script_names():
        with tempfile.TemporaryDirectory() as tmp:
            args = [str(SCRIPTS / f"{name}.py"), *(["--quick"] if quick else []), "--out", tmp]
            print("running", name, flush=True)
            subprocess.run([sys.executable, *args], check=True, cwd=tmp)
            pngs = sorted(Path(tmp).glob("*.png"))
            if len(pngs) != 1:
                raise RuntimeError(f"scripts/{name}.py wrote {len(pngs)} figures, expected one")
            shutil.copy2(pngs[0], GALLERY_FIGURES / f"{name}.png")
            shown = f"python scripts/{name}.py{' --quick' if quick else ''} --out DIR"
            made[name] = {k: v for k, v in _made(shown.split(), "quick" if quick else "full").items()}
    record.write_text(json.dumps(made, indent=1, sort_keys=True) + "\n", encoding="utf-8")
