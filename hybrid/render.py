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

import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import HybridError
from .outputs import replaced, replacing

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
]

PANEL_TITLES = ("a. rest", "b. peak inspiration", "c. end of expiration")
#: the same key frames of a scene that does not breathe
STILL_TITLES = ("a. rest", "b. largest displacement", "c. last frame")
#: MuJoCo geom groups drawn: MJCF models keep their wrapping surfaces, collision
#: shapes and helpers in groups 3 and above (myo-sim: wrapping 3, collision 4), which
#: would hide the membrane; MuJoCo's own viewer shows groups 0-2 by default too
SHOWN_GEOM_GROUPS = (0, 1, 2)


#: MuJoCo's mesh geom type (mjGEOM_MESH), and the radius (m) of the mark drawn for one
GEOM_MESH = 7
MESH_MARK_M = 0.006


def shown_geoms(geoms: list) -> list:
    """The geoms (`hybrid.record.body_geoms` dicts) a picture draws: those of
    `SHOWN_GEOM_GROUPS` (a geom without a group, from an older recording, counts as
    group 0) that are not transparent (rgba alpha > 0)."""
    return [g for g in geoms if int(g.get("group", 0)) in SHOWN_GEOM_GROUPS and float(g["rgba"][3]) > 0]


#: how the rest outline is drawn (dashed), in the section and on the 3D view
REST_STYLE = dict(colors="black", linestyles=(0, (3, 2)), linewidths=1.0)
_LIGHT = np.array([0.45, -0.35, 0.82]) / np.linalg.norm([0.45, -0.35, 0.82])


@dataclass
class Frames:
    """What the pictures need, one row a frame. t (n,) s; pos (n, nvert, 3) m;
    face_vert (nface, 3); vert_rgba (nvert, 4); body_pos (n, nbody, 3), body_quat
    (n, nbody, 4) (w, x, y, z) for `bodies`; geoms: dicts (body, type, size, pos,
    quat, rgba) in body frames; apex_descent, muscle, rib_lift (n,) for choosing the key frames and the labels;
    regions: the region names, vert_label (nvert,) each point's index in them (-1: none)."""

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
    rib_lift: np.ndarray | None = None
    regions: list = field(default_factory=list)
    vert_label: np.ndarray | None = None


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

    return Frames(
        scene=meta.get("scene", path.stem),
        t=pts["t"][:n],
        pos=pts["pos"][:n].astype(float),
        face_vert=meta["face_vert"],
        vert_rgba=meta["vert_rgba"],
        bodies=bodies,
        body_pos=body_pos,
        body_quat=body_quat,
        geoms=shown_geoms(meta.get("geoms", [])),
        apex_descent=series("/apex_descent"),
        muscle=series("/muscle_stiffness"),
        rib_lift=series("/rib_elevation"),
        regions=list(meta.get("regions", [])),
        vert_label=meta.get("vert_label"),
    )


def frames_from_scene(
    scene_arg: str | None,
    duration_s: float | None = None,
    *,
    full: bool = False,
    every_s: float = 0.01,
    overrides=(),
    without=(),
) -> Frames:
    """Run a scene (a TOML file or a built-in name, with "KEY=VALUE" `overrides` and
    the terms named in `without` removed) and keep its frames in memory. Without
    `duration_s`: the scene's duration if `full`, else up to the end of the first breath."""
    from .model import compile_scene
    from .observers.metrics import first_muscle
    from .record import body_geoms, region_colours
    from .resolve import resolve_scene
    from .run import RunFailed, run
    from .simulation import Simulation

    scene = resolve_scene(scene_arg, overrides=overrides, without=without)
    sim = Simulation(compile_scene(scene))
    if duration_s is None:
        duration_s = scene.duration_s
        _, breath = first_muscle(sim.model)
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
    names, label, colours = region_colours(sim.model)
    return Frames(
        scene=scene.name,
        t=np.asarray(keep["t"]),
        pos=np.asarray(keep["pos"]),
        face_vert=np.asarray(sim.model.mesh.face_vert),
        vert_rgba=colours,
        bodies=bodies,
        body_pos=np.asarray(keep["bpos"]) if bodies else None,
        body_quat=np.asarray(keep["bquat"]) if bodies else None,
        geoms=shown_geoms(body_geoms(sim.mj_model)) if sim.mj_model is not None else [],
        apex_descent=tr["apex_descent_mm"][idx][:n],
        muscle=_present(tr["muscle_n_per_m"][idx][:n]),
        rib_lift=_present(tr["rib_lift_mm"][idx][:n]),
        regions=names,
        vert_label=label,
    )


def _present(series: np.ndarray) -> np.ndarray | None:
    """A trace series, or None where the scene lacks its part (the trace holds NaN then)."""
    return None if np.all(np.isnan(series)) else series


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
    if fr.apex_descent is not None and np.ptp(fr.apex_descent[: end + 1]) > 0:
        peak = int(np.argmax(fr.apex_descent[: end + 1]))
    else:
        peak = int(np.argmax(np.linalg.norm(fr.pos[: end + 1] - fr.pos[:1], axis=2).max(axis=1)))
    if peak == end and top is not None and end > 0:  # still settling (a sag): the muscle's peak
        peak = top
    return 0, peak, end


def _quat_mat(q) -> np.ndarray:
    """(..., 4) quaternions (w, x, y, z) -> (..., 3, 3) rotation matrices."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


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
            # a mesh (a bone's surface) as a small mark where it is: its size is no radius,
            # and a disc of its extent would cover the membrane
            psize.append(MESH_MARK_M if g["type"] == GEOM_MESH else max(g["size"][:3]))
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


def _draw_panel(ax, fr: Frames, k: int, centre, half, *, membrane: bool, title: str, px_per_m: float, rest_cut=None):
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1), zoom=1.45)
    ax.view_init(elev=14, azim=-62)
    ax.computed_zorder = False  # the membrane over the bones: it is what the picture is about
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
        col[:, 3] = 0.85
        ax.add_collection3d(
            Poly3DCollection(tri, facecolors=np.clip(col, 0, 1), edgecolors=(0, 0, 0, 0.12), linewidths=0.3, zorder=3)
        )
    segs, radii, cols, pts, psize, pcols = _geom_segments(fr, k)
    if segs:
        widths = np.maximum(np.asarray(radii) * 2 * px_per_m * 0.72, 1.0)  # points (1/72 in)
        ax.add_collection3d(
            Line3DCollection(
                np.asarray(segs), colors=np.clip(np.asarray(cols), 0, 1), linewidths=widths, capstyle="round", zorder=1
            )
        )
    if pts:
        p = np.asarray(pts)
        ax.scatter(
            p[:, 0],
            p[:, 1],
            p[:, 2],
            s=(np.asarray(psize) * 2 * px_per_m * 0.72) ** 2,
            c=np.clip(np.asarray(pcols), 0, 1),
            zorder=2,
        )
    if rest_cut is not None:  # the rest outline (its mid-sagittal cut), over everything
        cut, y0 = rest_cut
        lines = np.stack([cut[:, :, 0], np.full(cut.shape[:2], y0), cut[:, :, 1]], axis=-1)
        ax.add_collection3d(Line3DCollection(lines, zorder=4, **REST_STYLE))


def breathes(fr: Frames) -> bool:
    """Whether the frames hold a breath: the muscle contracts to a peak and relaxes after
    it (a run stopped during the first inspiration has no peak inspiration nor end of
    expiration to name)."""
    m = fr.muscle
    if m is None or len(m) < 2 or not float(np.ptp(m)) > 0:
        return False
    tol = 1e-9 * float(np.abs(m).max())
    top = int(np.argmax(m >= m.max() - tol))
    return bool(m[top:].min() < m.max() - tol)


def panel_titles(fr: Frames) -> tuple:
    """The key frames' names: rest, peak inspiration, end of expiration where the scene
    breathes; rest, largest displacement, last frame where it does not."""
    return PANEL_TITLES if breathes(fr) else STILL_TITLES


def sagittal_section(pos: np.ndarray, face_vert: np.ndarray, y0: float) -> tuple[np.ndarray, np.ndarray]:
    """The membrane cut by the plane y = y0: segments (nseg, 2, 2) as (x, z) in m, and
    the face each comes from (nseg,). A point on the plane counts as above it, so that
    the segments join into closed outlines."""
    tri = pos[face_vert]
    d = tri[:, :, 1] - y0
    above = d >= 0
    ends = np.full((len(tri), 3, 2), np.nan)
    for e, (a, b) in enumerate(((0, 1), (1, 2), (2, 0))):
        cross = above[:, a] != above[:, b]
        w = d[cross, a] / (d[cross, a] - d[cross, b])  # signs differ: never 0 / 0
        p = tri[cross, a] + w[:, None] * (tri[cross, b] - tri[cross, a])
        ends[cross, e] = p[:, [0, 2]]
    hit = np.isfinite(ends[:, :, 0])
    keep = np.nonzero(hit.sum(axis=1) == 2)[0]
    segs = ends[keep][hit[keep]].reshape(-1, 2, 2)
    # a face touching the plane at one point only gives a segment of no length: left out
    real = np.any(segs[:, 0] != segs[:, 1], axis=1)
    return segs[real], keep[real]


def _nice_length(span_m: float) -> float:
    """A round length (1, 2 or 5 times a power of ten) of about a quarter of span_m."""
    target = 0.25 * span_m
    power = 10.0 ** np.floor(np.log10(target))
    return float(max(m * power for m in (1, 2, 5) if m * power <= target))


def _length_text(length_m: float) -> str:
    if length_m >= 1:
        return f"{length_m:g} m"
    return f"{length_m * 100:g} cm" if length_m >= 0.01 else f"{length_m * 1000:g} mm"


def _mm(value: float) -> str:
    text = f"{value:.1f}"
    return ("0.0" if text == "-0.0" else text) + " mm"


def _draw_section(ax, fr: Frames, k: int, y0: float, box, *, membrane: bool):
    """The mid-sagittal section of frame k over the rest outline, a scale bar, and the
    key figures (apex descent, rib lift) of the frame."""
    from matplotlib.collections import LineCollection

    (x_lo, x_hi), (z_lo, z_hi) = box
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(z_lo, z_hi)
    ax.set_aspect("equal")
    ax.set_axis_off()
    segs, _ = _geom_segments(fr, k)[:2]
    if segs:  # the bones seen from the side, faint, behind the membrane
        bones = np.asarray(segs)[:, :, [0, 2]]
        ax.add_collection(LineCollection(bones, colors=(0.55, 0.5, 0.42, 0.35), linewidths=3, zorder=1))
    if membrane:
        cut, faces = sagittal_section(fr.pos[k], fr.face_vert, y0)
        colours = np.clip(fr.vert_rgba[fr.face_vert[faces]].mean(axis=1), 0, 1)
        colours[:, 3] = 1.0
        ax.add_collection(LineCollection(cut, colors=colours, linewidths=2.4, zorder=2, label="deformed"))
        rest, _ = sagittal_section(fr.pos[0], fr.face_vert, y0)
        ax.add_collection(LineCollection(rest, zorder=3, label="rest", **REST_STYLE))
    length = _nice_length(x_hi - x_lo)
    x0, z0 = x_lo + 0.05 * (x_hi - x_lo), z_lo + 0.06 * (z_hi - z_lo)
    ax.plot([x0, x0 + length], [z0, z0], color="black", linewidth=2.5, solid_capstyle="butt", label="scale bar")
    ax.text(x0 + 0.5 * length, z0 + 0.015 * (z_hi - z_lo), _length_text(length), ha="center", va="bottom", fontsize=8)
    figures = []
    if fr.apex_descent is not None:
        figures.append(f"apex descent {_mm(fr.apex_descent[k])}")
    if fr.rib_lift is not None and fr.bodies:
        figures.append(f"rib lift {_mm(fr.rib_lift[k])}")
    if figures:
        ax.text(x_hi - 0.02 * (x_hi - x_lo), z0, "\n".join(figures), ha="right", va="bottom", fontsize=8)


def _section_box(fr: Frames, frames, y0: float):
    """The (x, z) limits every section shares: the membrane's cuts (the bones beyond them
    are cut off), square, with room below for the scale bar and the figures."""
    pts = np.concatenate([sagittal_section(fr.pos[k], fr.face_vert, y0)[0].reshape(-1, 2) for k in [0, *frames]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid, half = 0.5 * (lo + hi), 0.5 * float((hi - lo).max()) * 1.12
    return (mid[0] - half, mid[0] + half), (mid[1] - 1.3 * half, mid[1] + half)


def _legend(fig, fr: Frames, membrane: bool):
    """One legend under the panels: the regions' colours, the rest outline, the section."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = []
    if membrane and fr.vert_label is not None:
        label = np.asarray(fr.vert_label)
        for i, name in enumerate(fr.regions):
            where = np.nonzero(label == i)[0]
            if where.size:
                handles.append(Patch(facecolor=np.clip(fr.vert_rgba[where[0]], 0, 1), label=name))
        if (label < 0).any():
            handles.append(Patch(facecolor=np.clip(fr.vert_rgba[np.nonzero(label < 0)[0][0]], 0, 1), label="no region"))
    if membrane:
        handles.append(Line2D([], [], color="black", linestyle=(0, (3, 2)), linewidth=1.0, label="rest outline"))
    if fr.body_pos is not None and fr.geoms:
        handles.append(Line2D([], [], color=(0.55, 0.5, 0.42), linewidth=3, label="ribs and spine"))
    if handles:
        fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 7), fontsize=8, frameon=False)


def build_figure(fr: Frames, frames=None, *, membrane: bool = True, dpi: int = 100):
    """The figure: a 3D view over the mid-sagittal section for each of `frames`
    (default `key_frames(fr)`), and the legend. Returns (matplotlib Figure, frames)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = list(key_frames(fr) if frames is None else frames)
    centre, half = _bounds(fr, frames)
    y0 = float(fr.pos[0][:, 1].mean())
    box = _section_box(fr, frames, y0)
    titles = panel_titles(fr)
    width = 4.2 * len(frames)
    fig = plt.figure(figsize=(width, 8.0), dpi=dpi)
    grid = fig.add_gridspec(
        2, len(frames), height_ratios=(4.2, 3.4), left=0, right=1, bottom=0.07, top=0.93, wspace=0, hspace=0.0
    )
    px_per_m = 4.2 * dpi * 0.75 / (2 * half)  # roughly: the panel's width spans the box
    rest_cut = sagittal_section(fr.pos[0], fr.face_vert, y0)[0] if membrane else None
    for i, k in enumerate(frames):
        ax = fig.add_subplot(grid[0, i], projection="3d")
        _draw_panel(
            ax,
            fr,
            k,
            centre,
            half,
            membrane=membrane,
            title=titles[i] if i < len(titles) else "",
            px_per_m=px_per_m,
            rest_cut=(rest_cut, y0) if membrane else None,
        )
        _draw_section(fig.add_subplot(grid[1, i]), fr, k, y0, box, membrane=membrane)
    fig.suptitle(f"{fr.scene}: each view above its mid-sagittal section (the plane y = {y0 + 0.0:.3f} m)", fontsize=11)
    _legend(fig, fr, membrane)
    return fig, frames


def draw_figure(fr: Frames, path: str | Path, frames=None, *, membrane: bool = True, dpi: int = 100) -> list:
    """`build_figure` into a PNG. Returns the frame indices drawn."""
    import matplotlib.pyplot as plt

    fig, frames = build_figure(fr, frames, membrane=membrane, dpi=dpi)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with replaced(path, "wb") as f:  # never through a link left at path
            fig.savefig(f, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    return frames


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
    centre, half = _bounds(fr, picks[:: max(1, len(picks) // 20)] + [0])
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
            _draw_panel(ax, fr, k, centre, half, membrane=True, title=fr.scene, px_per_m=px_per_m)
            fig.canvas.draw()
            rgba = np.asarray(fig.canvas.buffer_rgba())
            writer.send(np.ascontiguousarray(rgba[:, :, :3]))
    finally:
        writer.close()
        plt.close(fig)


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
        raise HybridError(
            "view: no display (DISPLAY and WAYLAND_DISPLAY are not set); "
            "use `hybrid render` for pictures and video without one"
        )
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
    with _rigid.launch_viewer(m, d, SHOWN_GEOM_GROUPS) as v:
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
