"""MuJoCo's viewer for `hybrid view`: an empty world for membrane-only scenes, the
passive viewer itself, and segments drawn as capsules into a `MjvScene`."""

from __future__ import annotations

import mujoco
import numpy as np


def empty_world() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """A model with nothing in it, and its data: somewhere to look at a membrane."""
    model = mujoco.MjModel.from_xml_string("<mujoco/>")
    return model, mujoco.MjData(model)


def launch_viewer(model: mujoco.MjModel, data: mujoco.MjData, shown_groups=(0, 1, 2)):
    """MuJoCo's passive viewer on (model, data), a context manager (`mujoco.viewer`,
    imported here: it loads the windowing libraries), showing only the geom groups
    `shown_groups` (wrapping, collision and helper geoms, groups 3-5 in MJCF models,
    hidden: the membrane stays in view)."""
    import mujoco.viewer

    handle = mujoco.viewer.launch_passive(model, data)
    with handle.lock():
        show_geom_groups(handle.opt, shown_groups)
    return handle


def show_geom_groups(opt, shown_groups=(0, 1, 2)) -> None:
    """Set a `mujoco.MjvOption`'s geom groups: those of `shown_groups` on, the others off."""
    for g in range(len(opt.geomgroup)):
        opt.geomgroup[g] = 1 if g in shown_groups else 0


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
