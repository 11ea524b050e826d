"""Reading a recording back and plotting it: `hybrid.read` of a run.mcap.

    python scripts/read_recording.py [--recording RUN.mcap] [--out DIR] [--quick]

Without --recording, `hybrid run breathing --duration 4 --out OUT/run` makes one first
(the command line: `python -m hybrid run ...`). Writes recording.csv / recording.md
(per scalar channel: samples, smallest and largest value and when) and recording.png
(the scalar channels over time, and the apex point's height read from the recorded
membrane frames).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from _common import parse, pyplot, write_table

import hybrid


def make_recording(out: Path, scene: str, duration_s: float, overwrite: bool = False) -> Path:
    """A run.mcap from the command line, in out/run (replacing an earlier one there with `overwrite`)."""
    command = [sys.executable, "-m", "hybrid", "run", scene, "--duration", str(duration_s), "--out", str(out / "run")]
    subprocess.run(command + ["--overwrite"] * overwrite, check=True)
    return out / "run" / "run.mcap"


def main(argv=None) -> int:
    args = parse(
        __doc__,
        argv,
        "read_recording",
        lambda p: (
            p.add_argument("--recording", type=Path, default=None, help="a run.mcap (default: record one first)"),
            p.add_argument("--scene", default="breathing", help="the scene to record when no --recording is given"),
        ),
    )
    path = args.recording or make_recording(args.out, args.scene, 0.3 if args.quick else 4.0, args.overwrite)
    data = hybrid.read(path)
    scalars = sorted(k for k, v in data.items() if k.startswith("/") and isinstance(v, dict) and "value" in v)
    rows = []
    for topic in scalars:
        t, v = data[topic]["t"], data[topic]["value"]
        rows.append(
            {
                "channel": topic,
                "samples": len(v),
                "min": float(v.min()),
                "t_min_s": float(t[v.argmin()]),
                "max": float(v.max()),
                "t_max_s": float(t[v.argmax()]),
            }
        )
    write_table(rows, args.out, "recording")

    frames = data["membrane"]  # (nframe, nvert, 3): the apex is the highest point at rest
    apex = int(np.argmax(frames["pos"][0, :, 2]))
    plt = pyplot()
    fig, axes = plt.subplots(len(scalars) + 1, 1, figsize=(7, 1.5 * (len(scalars) + 1)), sharex=True)
    for ax, topic in zip(axes, scalars):
        ax.plot(data[topic]["t"], data[topic]["value"])
        ax.set_ylabel(topic, fontsize=7)
        ax.grid(alpha=0.3)
    axes[-1].plot(frames["t"], frames["pos"][:, apex, 2] * 1e3)
    axes[-1].set_ylabel(f"point {apex} z (mm)", fontsize=7)
    axes[-1].set_xlabel("time (s)")
    axes[-1].grid(alpha=0.3)
    axes[0].set_title(f"{data['model'].get('scene', path.stem)}: {path}", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out / "recording.png", dpi=100)
    plt.close(fig)
    print(f"{len(frames['t'])} frames of {frames['pos'].shape[1]} points -> {args.out}/recording.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
