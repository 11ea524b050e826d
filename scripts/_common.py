"""What the scripts share: their command line (--quick, --out) and their tables.

Each script is a `main(argv=None)` that writes a figure (PNG) and a table (CSV, and
the same as markdown, also printed) into --out; --quick runs a fraction of a second of
simulated time (a smoke test: the figures are then not the science).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path


def parse(doc: str, argv, name: str, more=None) -> argparse.Namespace:
    """The script's arguments; --out (default runs/scripts/NAME) created. A folder that
    already holds files is refused (one line, status 2) unless --overwrite, as `hybrid
    run --out` refuses one that holds a run: an earlier figure is not replaced unseen."""
    p = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a fraction of a second of simulated time (a smoke test)")
    p.add_argument(
        "--out", type=Path, default=Path("runs") / "scripts" / name, help=f"output folder (default runs/scripts/{name})"
    )
    p.add_argument("--overwrite", action="store_true", help="write into --out even if it holds files")
    if more is not None:
        more(p)
    args = p.parse_args(argv)
    held = sorted(args.out.iterdir()) if args.out.is_dir() else []
    if held and not args.overwrite:
        sys.stderr.write(
            f"{name}: error: --out: expected a folder that holds no earlier output, received {str(args.out)!r}, "
            f"which holds {len(held)} file(s) ({held[0].name}, ...); add --overwrite to replace them, or choose "
            "another --out\n"
        )
        raise SystemExit(2)
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        sys.stderr.write(
            f"{name}: error: --out: expected a folder that can be created, received {str(args.out)!r} ({exc.strerror})\n"
        )
        raise SystemExit(2) from None
    return args


def _cell(v) -> str:
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v + 0.0:.6g}"  # + 0.0: no "-0"
    return "" if v is None else str(v)


def write_table(rows: list[dict], out: Path, name: str) -> Path:
    """rows (dicts with the same keys) as out/NAME.csv and out/NAME.md; the markdown printed."""
    keys = list(rows[0])
    with open(out / f"{name}.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, keys)
        w.writeheader()
        w.writerows(rows)
    lines = ["| " + " | ".join(keys) + " |", "|" + " --- |" * len(keys)]
    lines += ["| " + " | ".join(_cell(r[k]) for k in keys) + " |" for r in rows]
    (out / f"{name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return out / f"{name}.csv"


def pyplot():
    """matplotlib's pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
