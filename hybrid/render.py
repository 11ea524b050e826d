"""Pictures of a run, headless: the paper's figure 4 (rest, peak inspiration, end of
expiration side by side) as a PNG, and an MP4 of the whole run.

`hybrid view SCENE` runs a scene live in MuJoCo's viewer where a display exists.

`hybrid render RUN.mcap|SCENE --out DIR` draws from a recording (`hybrid.record`) or
runs a scene first. Drawing is matplotlib's Agg backend with `mpl_toolkits.mplot3d`:
no GPU, no display, no system package beyond what the wheels bring. The membrane is a
shaded triangle mesh coloured by region (Lambert shading from a fixed light); the
MuJoCo geoms (ribs, spine: capsules and cylinders as thick segments, spheres as
points) are placed from the recorded body poses and the geoms' local frames.
The MP4 needs an encoder: `pip install -e .[video]` (imageio-ffmpeg, which ships its
own ffmpeg binary).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import HybridError

__all__ = ["Frames", "frames_from_recording", "frames_from_scene", "key_frames", "draw_figure",
           "render", "write_video", "view", "has_display", "membrane_edges", "draw_membrane"]

PANEL_TITLES = ("a. rest", "b. peak inspiration", "c. end of expiration")
_LIGHT = np.array([0.45, -0.35, 0.82]) / np.linalg.norm([0.45, -0.35, 0.82])


@dataclass
class Frames:
    """What the pictures need, one row a frame. t (n,) s; pos (n, nvert, 3) m;
    face_vert (nface, 3); vert_rgba (nvert, 4); body_pos (n, nbody, 3), body_quat
    (n, nbody, 4) (w, x, y, z) for `bodies`; geoms: dicts (body, type, size, pos,
    quat, rgba) in body frames; apex_descent, muscle (n,) for choosing the key frames."""
    scene: str
    t: np.ndarray
    pos: np.ndarray
    face_vert: np.ndarray
    vert_rgba: np.ndarray
    bodies: list = field(default_factory=list)
    body_pos: np.ndarray | None = None
    body_quat: np.ndarray | None = None
    geoms: list = field(default_factory=list)
    apex_descent: np.ndarray | None = None
    muscle: np.ndarray | None = None


def frames_from_recording(path: str | Path) -> Frames:
    """The frames of a `run.mcap` (hybrid.record)."""
    import warnings

    from .record import RecordingWarning, read

    path = Path(path)
    if not path.is_file():
        raise HybridError(f"recording {str(path)!r}: no such file")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RecordingWarning)
        data = read(path)
    if "model" not in data or "membrane" not in data:  # the error alone, on its one line
        raise HybridError(f"recording {str(path)!r}: no membrane frames (not written by hybrid run?)")
    for w in caught:  # a killed run's recording is drawn from what it holds: say so, on one line
        if issubclass(w.category, RecordingWarning):
            sys.stderr.write(f"hybrid: warning: {' '.join(str(w.message).split())}\n")
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    meta, pts = data["model"], data["membrane"]
    n = len(pts["t"])
    tf = data.get("/rigid/transforms")
    body_pos = body_quat = None
    bodies: list = []
    if tf is not None and len(tf["t"]):
        m = min(n, len(tf["t"]))
        n = m
        bodies, body_pos, body_quat = tf["bodies"], tf["pos"][:m], tf["quat"][:m]

    def series(topic):
        s = data.get(topic)
        return None if s is None or len(s["value"]) < n else s["value"][:n]

    return Frames(scene=meta.get("scene", path.stem), t=pts["t"][:n], pos=pts["pos"][:n].astype(float),
                  face_vert=meta["face_vert"], vert_rgba=meta["vert_rgba"], bodies=bodies,
                  body_pos=body_pos, body_quat=body_quat, geoms=meta.get("geoms", []),
                  apex_descent=series("/apex_descent"), muscle=series("/muscle_stiffness"))


def frames_from_scene(scene_arg: str | None, duration_s: float | None = None, *, full: bool = False,
                      every_s: float = 0.01) -> Frames:
    """Run a scene (a TOML file or a built-in name) and keep its frames in memory.
    Without `duration_s`: the scene's duration if `full`, else up to the end of the
    first breath."""
    from .model import compile_scene
    from .record import body_geoms, region_colours
    from .resolve import resolve_scene
    from .run import RunFailed, _breathing, run
    from .simulation import Simulation

    scene = resolve_scene(scene_arg)
    sim = Simulation(compile_scene(scene))
    if duration_s is None:
        duration_s = scene.duration_s
        _, breath = _breathing(sim.model)
        if breath is not None and not full:
            duration_s = min(duration_s, breath.onset_s + breath.period_s + 0.1)
    keep: dict = {"t": [], "pos": [], "bpos": [], "bquat": []}
    bodies = [sim.mj_model.body(b).name for b in range(1, sim.mj_model.nbody)] if sim.mj_model is not None else []
    next_t = [-1.0]

    def observe(s, trace):
        if s.time < next_t[0] - 1e-12:
            return
        next_t[0] = s.time + every_s - 1e-9
        keep["t"].append(s.time)
        keep["pos"].append(np.array(s.vert_pos))
        if bodies:
            keep["bpos"].append(np.array(s.mj_data.xpos[1:]))
            keep["bquat"].append(np.array(s.mj_data.xquat[1:]))

    try:
        result = run(sim, duration_s, observers=[observe])
    except RunFailed as failed:
        result = failed.result
    tr = result["trace"].arrays()
    n = len(keep["t"])
    idx = np.searchsorted(tr["t_s"], np.asarray(keep["t"]) - 1e-12)
    _, _, colours = region_colours(sim.model)
    return Frames(scene=scene.name, t=np.asarray(keep["t"]), pos=np.asarray(keep["pos"]),
                  face_vert=np.asarray(sim.model.mesh.face_vert), vert_rgba=colours, bodies=bodies,
                  body_pos=np.asarray(keep["bpos"]) if bodies else None,
                  body_quat=np.asarray(keep["bquat"]) if bodies else None,
                  geoms=body_geoms(sim.mj_model) if sim.mj_model is not None else [],
                  apex_descent=tr["apex_descent_mm"][idx][:n], muscle=tr["muscle_n_per_m"][idx][:n])


def key_frames(fr: Frames) -> tuple[int, int, int]:
    """(rest, peak inspiration, end of expiration) of the first breath: the first frame;
    the frame of largest apex descent up to the end of that breath (else the largest
    displacement; the muscle's peak if that is the breath's last frame, as in a shape
    still sagging under gravity); the end of the breath, where the muscle, relaxed
    after its first peak, starts to contract again (else the last frame)."""
    n = len(fr.t)
    end = n - 1
    m = fr.muscle
    top = None
    if m is not None and np.ptp(m) > 0:
        tol = 1e-9 * np.abs(m).max()
        top = int(np.argmax(m >= m.max() - tol))  # the first contraction's peak
        for i in range(top + 1, n):
            if m[i] > m[i - 1] + tol:  # contracting again: the breath ended at i - 1
                end = i - 1
                break
    if fr.apex_descent is not None and np.ptp(fr.apex_descent[:end + 1]) > 0:
        peak = int(np.argmax(fr.apex_descent[:end + 1]))
    else:
        peak = int(np.argmax(np.linalg.norm(fr.pos[:end + 1] - fr.pos[:1], axis=2).max(axis=1)))
    if peak == end and top is not None and end > 0:  # still settling (a sag): the muscle's peak
        peak = top
    return 0, peak, end


def _quat_mat(q) -> np.ndarray:
    """(..., 4) quaternions (w, x, y, z) -> (..., 3, 3) rotation matrices."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def _geom_segments(fr: Frames, k: int):
    """World segments (nseg, 2, 3), radii and colours of the capsule/cylinder geoms at
    frame k; spheres/boxes/ellipsoids as points (npt, 3) with sizes and colours."""
    from .record import GEOM_CAPSULE, GEOM_CYLINDER

    segs, radii, cols, pts, psize, pcols = [], [], [], [], [], []
    if fr.body_pos is None:
        return segs, radii, cols, pts, psize, pcols
    index = {name: i for i, name in enumerate(fr.bodies)}
    for g in fr.geoms:
        b = index.get(g["body"])
        if b is None:
            continue
        Rb = _quat_mat(fr.body_quat[k, b])
        centre = fr.body_pos[k, b] + Rb @ np.asarray(g["pos"])
        if g["type"] in (GEOM_CAPSULE, GEOM_CYLINDER):
            axis = Rb @ _quat_mat(g["quat"])[:, 2]
            half = g["size"][1]
            segs.append([centre - half * axis, centre + half * axis])
            radii.append(g["size"][0])
            cols.append(g["rgba"])
        else:
            pts.append(centre)
            psize.append(max(g["size"][:3]))
            pcols.append(g["rgba"])
    return segs, radii, cols, pts, psize, pcols


def _bounds(fr: Frames, frames) -> tuple[np.ndarray, float]:
    pts = [fr.pos[k] for k in frames]
    for k in frames:
        segs = _geom_segments(fr, k)[0]
        if segs:
            pts.append(np.asarray(segs).reshape(-1, 3))
    allp = np.concatenate(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    return 0.5 * (lo + hi), 0.5 * float((hi - lo).max()) * 1.05


def _draw_panel(ax, fr: Frames, k: int, centre, half, *, membrane: bool, title: str, px_per_m: float):
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1), zoom=1.45)
    ax.view_init(elev=14, azim=-62)
    ax.computed_zorder = False  # the bones over the membrane (a schematic, like the paper's figure)
    ax.set_axis_off()
    ax.set_title(title + f"  (t = {fr.t[k]:.2f} s)", fontsize=10)
    if membrane:
        tri = fr.pos[k][fr.face_vert]  # (nface, 3, 3)
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        # faces wound either way: light the side that faces the viewer's half-space
        shade = 0.35 + 0.65 * np.abs(nrm @ _LIGHT)
        col = fr.vert_rgba[fr.face_vert].mean(axis=1)
        col[:, :3] *= shade[:, None]
        col[:, 3] = 0.9
        ax.add_collection3d(Poly3DCollection(tri, facecolors=np.clip(col, 0, 1),
                                             edgecolors=(0, 0, 0, 0.12), linewidths=0.3, zorder=1))
    segs, radii, cols, pts, psize, pcols = _geom_segments(fr, k)
    if segs:
        widths = np.maximum(np.asarray(radii) * 2 * px_per_m * 0.72, 1.0)  # points (1/72 in)
        ax.add_collection3d(Line3DCollection(np.asarray(segs), colors=np.clip(np.asarray(cols), 0, 1),
                                             linewidths=widths, capstyle="round", zorder=2))
    if pts:
        p = np.asarray(pts)
        ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=(np.asarray(psize) * 2 * px_per_m * 0.72) ** 2,
                   c=np.clip(np.asarray(pcols), 0, 1), zorder=3)


def draw_figure(fr: Frames, path: str | Path, frames=None, *, membrane: bool = True, dpi: int = 100) -> list:
    """The three panels side by side (`frames`: default `key_frames(fr)`) into a PNG.
    Returns the frame indices drawn."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = list(key_frames(fr) if frames is None else frames)
    centre, half = _bounds(fr, frames)
    fig = plt.figure(figsize=(4.2 * len(frames), 4.6), dpi=dpi)
    px_per_m = 4.2 * dpi * 0.75 / (2 * half)  # roughly: the panel's width spans the box
    for i, k in enumerate(frames):
        ax = fig.add_subplot(1, len(frames), i + 1, projection="3d")
        _draw_panel(ax, fr, k, centre, half, membrane=membrane,
                    title=PANEL_TITLES[i] if i < len(PANEL_TITLES) else "", px_per_m=px_per_m)
    fig.suptitle(fr.scene, fontsize=11)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.9, wspace=0)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return frames


def write_video(fr: Frames, path: str | Path, *, fps: int = 25, every_s: float | None = None, dpi: int = 80) -> int:
    """An MP4 of the run in real time (one picture every 1/fps s of simulated time).
    Needs imageio-ffmpeg (`pip install -e .[video]`). Returns the number of pictures."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise HybridError("--video: no MP4 encoder; install one with `pip install -e .[video]` (imageio-ffmpeg)") from None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    step = every_s if every_s is not None else 1.0 / fps
    picks, nxt = [], -1.0
    for k, t in enumerate(fr.t):
        if t >= nxt - 1e-9:
            picks.append(k)
            nxt = t + step
    centre, half = _bounds(fr, picks[:: max(1, len(picks) // 20)] + [0])
    fig = plt.figure(figsize=(6.4, 6.4), dpi=dpi)  # 512 x 512: both even, as H.264 needs
    px_per_m = 6.4 * dpi * 0.75 / (2 * half)
    w, h = fig.canvas.get_width_height()
    writer = imageio_ffmpeg.write_frames(str(path), (w, h), fps=fps, quality=7, macro_block_size=16)
    writer.send(None)
    try:
        for k in picks:
            fig.clf()
            ax = fig.add_subplot(1, 1, 1, projection="3d")
            _draw_panel(ax, fr, k, centre, half, membrane=True, title=fr.scene, px_per_m=px_per_m)
            fig.canvas.draw()
            rgba = np.asarray(fig.canvas.buffer_rgba())
            writer.send(np.ascontiguousarray(rgba[:, :, :3]))
    finally:
        writer.close()
        plt.close(fig)
    return len(picks)


def render(source: str | None, out_dir: str | Path, *, video: bool = False, duration_s: float | None = None) -> dict:
    """Draw `source` (a run.mcap, or a scene to run) into out_dir: figure4.png, and
    run.mp4 with `video`. Returns {"figure": path, "frames": (rest, peak, end) times, "video": path|None}."""
    out = Path(out_dir)
    if source is not None and source.endswith(".mcap"):
        fr = frames_from_recording(source)
    else:
        fr = frames_from_scene(source, duration_s, full=video)
    if len(fr.t) < 2:
        raise HybridError(f"{source}: fewer than two frames to draw")
    fig_path = out / "figure4.png"
    picked = draw_figure(fr, fig_path)
    result = {"figure": fig_path, "frames": [float(fr.t[k]) for k in picked], "video": None}
    if video:
        result["video"] = out / "run.mp4"
        write_video(fr, result["video"])
    return result


# ---------------------------------------------------------------- live viewing
def has_display() -> bool:
    """Whether a window can open: an X11 or Wayland display on Linux; assumed elsewhere."""
    import os
    import sys
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def membrane_edges(model) -> tuple[np.ndarray, np.ndarray]:
    """The membrane's edges (nedge, 2) and their colours (nedge, 4) float32 (the mean of
    their points' region colours)."""
    from .record import region_colours

    _, _, colours = region_colours(model)
    face = np.asarray(model.mesh.face_vert)
    edges = np.unique(np.sort(np.concatenate([face[:, [0, 1]], face[:, [1, 2]], face[:, [2, 0]]]), axis=1), axis=0)
    return edges, colours[edges].mean(axis=1).astype(np.float32)


def draw_membrane(scn, pos: np.ndarray, edges: np.ndarray, edge_rgba: np.ndarray, width_m: float = 0.0015) -> int:
    """Replace the geoms of a MuJoCo `MjvScene` (the viewer's user scene) by the membrane's
    edges as thin capsules at positions `pos`. Returns the number of geoms drawn."""
    from .rigid import draw_capsules  # MuJoCo only when drawing

    return draw_capsules(scn, pos, edges, edge_rgba, width_m)


def view(scene_arg: str | None, *, duration_s: float | None = None) -> dict:
    """Run a scene live in MuJoCo's passive viewer, the membrane drawn each frame as
    its edges (user scene geoms) coloured by region; in real time, until the window
    closes or the scene's duration ends. Returns {"frames": frames shown,
    "membrane_geoms": geoms of the last one, "edges": the membrane's edges, "t_s":
    simulated time}. Raises HybridError where no display exists."""
    if not has_display():
        raise HybridError("view: no display (DISPLAY and WAYLAND_DISPLAY are not set); "
                          "use `hybrid render` for pictures and video without one")
    import threading
    import time as _time

    from . import rigid as _rigid  # MuJoCo's viewer
    from .model import compile_scene
    from .resolve import resolve_scene
    from .simulation import Simulation

    scene = resolve_scene(scene_arg)
    sim = Simulation(compile_scene(scene))
    m, d = (sim.mj_model, sim.mj_data) if sim.mj_model is not None else (None, None)
    if m is None:  # membrane only: an empty world to look at it in
        m, d = _rigid.empty_world()
    edges, edge_rgba = membrane_edges(sim.model)
    frame_steps = max(1, int(round(1 / 60 / sim.model.dt_s)))
    end = scene.duration_s if duration_s is None else duration_s
    before = set(threading.enumerate())
    frames = drawn = 0
    with _rigid.launch_viewer(m, d) as v:
        window = [t for t in threading.enumerate() if t not in before]  # the viewer's own thread
        wall0 = _time.perf_counter()
        while v.is_running() and sim.time < end:
            try:
                sim.step(frame_steps)
            except HybridError as exc:
                print(f"hybrid: {exc}")
                break
            with v.lock():
                drawn = draw_membrane(v.user_scn, sim.vert_pos, edges, edge_rgba)
            v.sync()
            frames += 1
            ahead = sim.time - (_time.perf_counter() - wall0)
            if ahead > 0:
                _time.sleep(ahead)
    # the window closes on the viewer's thread: wait for it, or the exit handlers close
    # the display while it still renders (a crash at exit under software OpenGL)
    for t in window:
        t.join(timeout=10.0)
    return {"frames": frames, "membrane_geoms": drawn, "edges": len(edges), "t_s": sim.time}
