"""A scene run live in MuJoCo's viewer, the membrane drawn each frame as its edges."""

from __future__ import annotations

import numpy as np

from ..errors import HybridError
from .frames import SHOWN_GEOM_GROUPS

__all__ = ["has_display", "membrane_edges", "draw_membrane", "view"]


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
    from ..record import region_colours

    _, _, colours = region_colours(model)
    face = np.asarray(model.mesh.face_vert)
    edges = np.unique(np.sort(np.concatenate([face[:, [0, 1]], face[:, [1, 2]], face[:, [2, 0]]]), axis=1), axis=0)
    return edges, colours[edges].mean(axis=1).astype(np.float32)


def draw_membrane(scn, pos: np.ndarray, edges: np.ndarray, edge_rgba: np.ndarray, width_m: float = 0.0015) -> int:
    """Replace the geoms of a MuJoCo `MjvScene` (the viewer's user scene) by the membrane's
    edges as thin capsules at positions `pos`. Returns the number of geoms drawn."""
    from ..rigid import draw_capsules  # MuJoCo only when drawing

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

    from .. import rigid as _rigid  # MuJoCo's viewer
    from ..model import compile_scene
    from ..resolve import resolve_scene
    from ..simulation import Simulation

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
