"""An MP4 of a run in real time, one 3D view a picture."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import HybridError
from ..outputs import replacing
from .figure import draw_panel, view_bounds
from .frames import Frames

__all__ = ["write_video"]


def write_video(fr: Frames, path: str | Path, *, fps: int = 25, every_s: float | None = None, dpi: int = 80) -> int:
    """An MP4 of the run in real time (one picture every 1/fps s of simulated time).
    Needs imageio-ffmpeg (`pip install -e .[video]`). Returns the number of pictures."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise HybridError(
            "--video: no MP4 encoder; install one with `pip install -e .[video]` (imageio-ffmpeg)"
        ) from None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    step = every_s if every_s is not None else 1.0 / fps
    picks, nxt = [], -1.0
    for k, t in enumerate(fr.t):
        if t >= nxt - 1e-9:
            picks.append(k)
            nxt = t + step
    centre, half = view_bounds(fr, picks[:: max(1, len(picks) // 20)] + [0])
    fig = plt.figure(figsize=(6.4, 6.4), dpi=dpi)  # 512 x 512: both even, as H.264 needs
    px_per_m = 6.4 * dpi * 0.75 / (2 * half)
    w, h = fig.canvas.get_width_height()
    with replacing(path) as tmp:  # ffmpeg writes a fresh file, renamed over path: never through a link
        _send_video(
            fig,
            fr,
            picks,
            imageio_ffmpeg.write_frames(str(tmp), (w, h), fps=fps, quality=7, macro_block_size=16),
            centre,
            half,
            px_per_m,
        )
    return len(picks)


def _send_video(fig, fr, picks, writer, centre, half, px_per_m) -> None:
    import matplotlib.pyplot as plt

    writer.send(None)
    try:
        for k in picks:
            fig.clf()
            ax = fig.add_subplot(1, 1, 1, projection="3d")
            draw_panel(ax, fr, k, centre, half, membrane=True, title=fr.scene, px_per_m=px_per_m)
            fig.canvas.draw()
            rgba = np.asarray(fig.canvas.buffer_rgba())
            writer.send(np.ascontiguousarray(rgba[:, :, :3]))
    finally:
        writer.close()
        plt.close(fig)
