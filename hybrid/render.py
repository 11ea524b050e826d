"""Pictures of a run, headless: the paper's figure 4 (rest, peak inspiration, end of
expiration side by side) as a PNG, and an MP4 of the whole run.

`hybrid view SCENE` runs a scene live in MuJoCo's viewer where a display exists.

`hybrid render RUN.mcap|SCENE --out DIR` draws from a recording (`hybrid.record`) or
runs a scene first (with `--set` and `--without` as `hybrid run`). Each panel has the
3D view and, below it, the mid-sagittal section (the plane y = the rest centroid's y:
x anterior, z cranial in the packaged scenes) of the deformed membrane, coloured by
region, over the rest outline (dashed, also drawn on the 3D view), with a scale bar;
one legend names the region colours. The panels are called rest, peak inspiration and
end of expiration only where the scene breathes (its muscle's stiffness varies). Drawing is matplotlib's Agg backend with `mpl_toolkits.mplot3d`:
no GPU, no display, no system package beyond what the wheels bring. The membrane is a
shaded triangle mesh coloured by region (Lambert shading from a fixed light); the
MuJoCo geoms (ribs, spine: capsules and cylinders as thick segments, spheres as
points) are placed from the recorded body poses and the geoms' local frames.
The MP4 needs an encoder: `pip install -e .[video]` (imageio-ffmpeg, which ships its
own ffmpeg binary).
"""

from __future__ import annotations

from pathlib import Path

from .errors import HybridError
from .pictures.figure import build_figure, draw_figure, sagittal_section
from .pictures.frames import (
    PANEL_TITLES,
    SHOWN_GEOM_GROUPS,
    STILL_TITLES,
    Frames,
    breathes,
    frames_from_recording,
    frames_from_scene,
    key_frames,
    panel_titles,
    shown_geoms,
)
from .pictures.live import draw_membrane, has_display, membrane_edges, view
from .pictures.video import write_video

__all__ = [
    "Frames",
    "frames_from_recording",
    "frames_from_scene",
    "key_frames",
    "breathes",
    "panel_titles",
    "sagittal_section",
    "build_figure",
    "draw_figure",
    "render",
    "write_video",
    "view",
    "has_display",
    "membrane_edges",
    "draw_membrane",
    "shown_geoms",
    "SHOWN_GEOM_GROUPS",
    "PANEL_TITLES",
    "STILL_TITLES",
]


def _died(recording: Path) -> str | None:
    """Why the run that wrote `recording` is no longer running though its summary says so, or None."""
    from .outputs import run_status

    run = run_status(recording.parent) if recording.name == "run.mcap" else None
    return run.get("died") if run is not None else None


def render(
    source: str | None,
    out_dir: str | Path,
    *,
    video: bool = False,
    duration_s: float | None = None,
    overrides=(),
    without=(),
) -> dict:
    """Draw `source` (a run.mcap, or a scene to run with "KEY=VALUE" `overrides` and the
    terms named in `without` removed) into out_dir: figure4.png, and run.mp4 with
    `video`. Returns {"figure": path, "frames": the key frames' times (s), "titles":
    their names (`panel_titles`), "video": path|None}."""
    out = Path(out_dir)
    if source is not None and source.endswith(".mcap"):
        given = "--set" if overrides else "--without" if without else None
        if given:
            raise HybridError(
                f"{given}: changes a scene before it runs; expected a scene, received the recording "
                f"{source!r} (run the scene again with {given}, or render the scene itself)"
            )
        fr = frames_from_recording(source)
        died = _died(Path(source))
    else:
        died = None
        fr = frames_from_scene(source, duration_s, full=video, overrides=overrides, without=without)
    if len(fr.t) < 2:
        raise HybridError(f"{source}: fewer than two frames to draw")
    fig_path = out / "figure4.png"
    picked = draw_figure(fr, fig_path)
    result = {
        "figure": fig_path,
        "frames": [float(fr.t[k]) for k in picked],
        "titles": [t.split(". ", 1)[-1] for t in panel_titles(fr)],
        "video": None,
        "died": died,
    }
    if video:
        result["video"] = out / "run.mp4"
        write_video(fr, result["video"])
    return result
