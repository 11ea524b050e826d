"""The paper's figure 4: a 3D view of each key frame over its mid-sagittal section,
coloured by region over the rest outline, with a scale bar and one legend."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..outputs import replaced
from ..record.schemas import GEOM_MESH
from .frames import Frames, key_frames, panel_titles

__all__ = ["bone_points", "sagittal_section", "view_bounds", "draw_panel", "build_figure", "draw_figure"]

#: the radius (m) of the mark drawn for a mesh geom recorded without its points
MESH_MARK_M = 0.006


#: how the rest outline is drawn (dashed), in the section and on the 3D view
REST_STYLE = dict(colors="black", linestyles=(0, (3, 2)), linewidths=1.0)
_LIGHT = np.array([0.45, -0.35, 0.82]) / np.linalg.norm([0.45, -0.35, 0.82])


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
    from ..record import GEOM_CAPSULE, GEOM_CYLINDER

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
        elif g["type"] == GEOM_MESH and "points" in g:  # a bone's surface: drawn as its dots (`bone_points`)
            continue
        else:
            pts.append(centre)
            # a mesh (a bone's surface) recorded without its points, as a small mark where it is:
            # its size is no radius, and a disc of its extent would cover the membrane
            psize.append(MESH_MARK_M if g["type"] == GEOM_MESH else max(g["size"][:3]))
            pcols.append(g["rgba"])
    return segs, radii, cols, pts, psize, pcols


def bone_points(fr: Frames, k: int) -> tuple[np.ndarray, np.ndarray]:
    """World points (n, 3) of the model's mesh geoms (its bones' surfaces: the vertices
    `hybrid.record.body_geoms` keeps) at frame k, and their colours (n, 4)."""
    out, colours = [], []
    if fr.body_pos is not None:
        index = {name: i for i, name in enumerate(fr.bodies)}
        for g in fr.geoms:
            b = index.get(g["body"])
            if g["type"] != GEOM_MESH or "points" not in g or (b is None and g.get("body_id") != 0):
                continue
            local = np.asarray(g["pos"]) + np.asarray(g["points"]) @ _quat_mat(g["quat"]).T
            if b is None:  # the world's own geoms: fixed, turned with the frames
                out.append(local @ np.asarray(fr.axes).T)
            else:
                out.append(fr.body_pos[k, b] + local @ _quat_mat(fr.body_quat[k, b]).T)
            colours.append(np.repeat(np.asarray(g["rgba"], float)[None], len(local), axis=0))
    if not out:
        return np.zeros((0, 3)), np.zeros((0, 4))
    return np.concatenate(out), np.concatenate(colours)


#: the bones' dots: their size (points^2), opacity, and how near the section's plane (m) a dot is cut
BONE_DOT = 2.5
BONE_ALPHA = 0.5
BONE_RGB = (0.55, 0.5, 0.42)
BONE_SLAB_M = 0.004


def view_bounds(fr: Frames, frames) -> tuple[np.ndarray, float]:
    pts = [fr.pos[k] for k in frames]
    for k in frames:
        segs = _geom_segments(fr, k)[0]
        if segs:
            pts.append(np.asarray(segs).reshape(-1, 3))
    allp = np.concatenate(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    return 0.5 * (lo + hi), 0.5 * float((hi - lo).max()) * 1.05


def draw_panel(ax, fr: Frames, k: int, centre, half, *, membrane: bool, title: str, px_per_m: float, rest_cut=None):
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
    bones, _ = bone_points(fr, k)
    inside = np.all(np.abs(bones - centre) <= half, axis=1)  # mplot3d does not clip
    if inside.any():  # in the bones' colour of the section (a model's own is often near white)
        b = bones[inside]
        ax.scatter(b[:, 0], b[:, 1], b[:, 2], s=BONE_DOT, color=BONE_RGB + (BONE_ALPHA,), linewidths=0, zorder=1)
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


def _plane(left, y0: float) -> str:
    """The section's plane in the model's own coordinates: `y0` m along its left, `left`."""
    k = int(np.argmax(np.abs(left)))
    if abs(abs(left[k]) - 1.0) < 1e-9:
        return f"the plane {'xyz'[k]} = {round(y0 * left[k], 3) + 0.0:.3f} m"
    return f"the plane {round(y0, 3) + 0.0:.3f} m along the body's left"


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
    bones, _ = bone_points(fr, k)
    cut_bones = (np.abs(bones[:, 1] - y0) <= BONE_SLAB_M) & (bones[:, 0] >= x_lo) & (bones[:, 0] <= x_hi)
    cut_bones &= (bones[:, 2] >= z_lo) & (bones[:, 2] <= z_hi)
    if cut_bones.any():  # the bones the plane cuts (the spine, the sternum), behind the membrane
        ax.scatter(bones[cut_bones, 0], bones[cut_bones, 2], s=2 * BONE_DOT, color=BONE_RGB, zorder=1)
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
    if len(bone_points(fr, 0)[0]):
        handles.append(
            Line2D([], [], color=(0.55, 0.5, 0.42), marker=".", linestyle="", label="the model's bones (dots)")
        )
    if handles:
        fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 7), fontsize=8, frameon=False)


def build_figure(fr: Frames, frames=None, *, membrane: bool = True, dpi: int = 100):
    """The figure: a 3D view over the mid-sagittal section for each of `frames`
    (default `key_frames(fr)`), and the legend. Returns (matplotlib Figure, frames)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = list(key_frames(fr) if frames is None else frames)
    centre, half = view_bounds(fr, frames)
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
        draw_panel(
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
    fig.suptitle(f"{fr.scene}: each view above its mid-sagittal section ({_plane(fr.left, y0)})", fontsize=11)
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
