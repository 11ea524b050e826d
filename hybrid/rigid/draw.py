"""MuJoCo's viewer for `hybrid view`: an empty world for membrane-only scenes, the
passive viewer itself, and segments drawn as capsules into a `MjvScene`."""

from __future__ import annotations

import mujoco
import numpy as np


def empty_world() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """A model with nothing in it, and its data: somewhere to look at a membrane."""
    model = mujoco.MjModel.from_xml_string("<mujoco/>")
    return model, mujoco.MjData(model)


def launch_viewer(model: mujoco.MjModel, data: mujoco.MjData):
    """MuJoCo's passive viewer on (model, data), a context manager (`mujoco.viewer`,
    imported here: it loads the windowing libraries)."""
    import mujoco.viewer

    return mujoco.viewer.launch_passive(model, data)


def draw_capsules(scn, pos: np.ndarray, edges: np.ndarray, edge_rgba: np.ndarray, width_m: float) -> int:
    """Replace the geoms of `scn` (a `mujoco.MjvScene`) by one capsule of width
    `width_m` per edge (nedge, 2) between positions `pos` (m), coloured `edge_rgba`
    (nedge, 4); as many as the scene holds. Returns the number of geoms drawn."""
    capsule = mujoco.mjtGeom.mjGEOM_CAPSULE
    zero, eye = np.zeros(3), np.eye(3).ravel()
    scn.ngeom = 0
    for (i, j), rgba in zip(edges, edge_rgba):
        if scn.ngeom >= scn.maxgeom:
            break
        g = scn.geoms[scn.ngeom]
        mujoco.mjv_initGeom(g, capsule, zero, zero, eye, rgba)
        mujoco.mjv_connector(g, capsule, width_m, pos[i], pos[j])
        scn.ngeom += 1
    return scn.ngeom
