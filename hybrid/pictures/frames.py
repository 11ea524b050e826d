"""The frames pictures are drawn from, read from a recording or a scene run in memory,
and which of them are the key frames (rest, peak inspiration, end of expiration)."""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import HybridError

__all__ = [
    "turned",
    "PANEL_TITLES",
    "STILL_TITLES",
    "SHOWN_GEOM_GROUPS",
    "shown_geoms",
    "Frames",
    "frames_from_recording",
    "frames_from_scene",
    "key_frames",
    "breathes",
    "panel_titles",
]

#: the key frames' names of a scene that breathes
PANEL_TITLES = ("a. rest", "b. peak inspiration", "c. end of expiration")
#: the same key frames of a scene that does not breathe
STILL_TITLES = ("a. rest", "b. largest displacement", "c. last frame")
#: MuJoCo geom groups drawn: MJCF models keep their wrapping surfaces, collision
#: shapes and helpers in groups 3 and above (myo-sim: wrapping 3, collision 4), which
#: would hide the membrane; MuJoCo's own viewer shows groups 0-2 by default too
SHOWN_GEOM_GROUPS = (0, 1, 2)


def shown_geoms(geoms: list) -> list:
    """The geoms (`hybrid.record.body_geoms` dicts) a picture draws: those of
    `SHOWN_GEOM_GROUPS` (a geom without a group, from an older recording, counts as
    group 0) that are not transparent (rgba alpha > 0)."""
    return [g for g in geoms if int(g.get("group", 0)) in SHOWN_GEOM_GROUPS and float(g["rgba"][3]) > 0]


@dataclass
class Frames:
    """What the pictures need, one row a frame. t (n,) s; pos (n, nvert, 3) m;
    face_vert (nface, 3); vert_rgba (nvert, 4); body_pos (n, nbody, 3), body_quat
    (n, nbody, 4) (w, x, y, z) for `bodies`; geoms: dicts (body, type, size, pos,
    quat, rgba) in body frames; apex_descent, muscle, rib_lift (n,) for choosing the key frames and the labels;
    regions: the region names, vert_label (nvert,) each point's index in them (-1: none);
    left: the model's own direction that the frames' +y is, axes the turn from the model's frame
    (rows: the body's axes in it; `turned`: the frames are in the body's axes, x anterior, y left,
    z cranial, whatever the model's)."""

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
    left: tuple = (0.0, 1.0, 0.0)
    axes: np.ndarray = field(default_factory=lambda: np.eye(3))


def turned(fr: Frames, anterior, cranial) -> Frames:
    """fr in the body's axes: x anterior, y left (cranial x anterior), z cranial, as the pictures
    draw a body (the packaged trunk's frame, the paper's); the points, the bodies' positions and
    orientations turned about the origin (the geoms stay in their bodies' frames)."""
    from scipy.spatial.transform import Rotation

    a, c = np.asarray(anterior, float), np.asarray(cranial, float)
    rot = np.stack([a, np.cross(c, a), c])  # rows: the body's axes in the model's frame
    if np.allclose(rot, np.eye(3)):
        return fr
    quat = None
    if fr.body_quat is not None:  # (w, x, y, z), scipy's (x, y, z, w)
        q = fr.body_quat.reshape(-1, 4)[:, [1, 2, 3, 0]]
        quat = (Rotation.from_matrix(rot) * Rotation.from_quat(q)).as_quat()[:, [3, 0, 1, 2]]
        quat = quat.reshape(fr.body_quat.shape)
    return dataclasses.replace(
        fr,
        pos=fr.pos @ rot.T,
        body_pos=None if fr.body_pos is None else fr.body_pos @ rot.T,
        body_quat=quat,
        left=tuple(float(v) for v in rot[1]),
        axes=rot,
    )


def frames_from_recording(path: str | Path) -> Frames:
    """The frames of a `run.mcap` (hybrid.record)."""
    import warnings

    from ..record import RecordingWarning, read

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

    frames = Frames(
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
        muscle=series("/muscle") if "/muscle" in data else series("/muscle_stiffness"),  # its name before 0.20
        rib_lift=series("/rib_elevation"),
        regions=list(meta.get("regions", [])),
        vert_label=meta.get("vert_label"),
    )
    # a recording made before the axes were written: the packaged trunk's frame
    return turned(frames, meta.get("anterior", (1.0, 0.0, 0.0)), meta.get("cranial", (0.0, 0.0, 1.0)))


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
    from ..model import compile_scene
    from ..observers.metrics import first_muscle
    from ..record import body_geoms, region_colours
    from ..resolve import resolve_scene
    from ..run import RunFailed, run
    from ..scene import body_axes
    from ..simulation import Simulation

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
    frames = Frames(
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
    return turned(frames, *body_axes(scene))


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
