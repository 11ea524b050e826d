"""Timings of MuJoCo alone, for `hybrid bench`: bare `mj_step` calls on an MJCF, and
MuJoCo's own 2D flex sphere (an elastic shell without volume constraint)."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from hybrid.errors import RigidError

from .mjcf import compile_spec, load_spec


def bare_stepper(path: str | Path):
    """A timer of bare `mj_step` calls (from Python) on the MJCF at `path`:
    returns f(nstep) -> seconds per step."""
    import time
    model = compile_spec(load_spec(path))
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data)

    def timed(nstep: int) -> float:
        mujoco.mj_resetData(model, data)
        t0 = time.perf_counter()
        for _ in range(nstep):
            mujoco.mj_step(model, data)
        return (time.perf_counter() - t0) / nstep

    return timed


def flex_sphere_run(vert_pos: np.ndarray, face_vert: np.ndarray, *, duration_s: float = 1.0,
                    total_kg: float = 4.0, young_pa: float = 3e4, thickness_m: float = 0.01,
                    timestep_s: float = 1e-3) -> dict:
    """MuJoCo's own closed 2D flex sphere (elastic shell) dropped on a plane under gravity.

    vert_pos (n, 3) m around the origin, face_vert (nface, 3) outward. Returns
    {"nvert", "us_per_step", "volume_change"} with the relative volume change
    after `duration_s`; MuJoCo has no volume constraint. Raises RigidError if
    MuJoCo reset the simulation (a blow-up).
    """
    import time
    pts = " ".join(f"{x:.6f}" for x in np.asarray(vert_pos, float).ravel())
    el = " ".join(str(int(i)) for i in np.asarray(face_vert).ravel())
    z0 = float(-np.min(vert_pos[:, 2])) + 0.005
    xml = f"""<mujoco>
  <option timestep="{timestep_s}" integrator="Euler" gravity="0 0 -9.81"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <flexcomp name="ball" type="direct" dim="2" pos="0 0 {z0}" radius="0.004" mass="{total_kg}"
              point="{pts}" element="{el}">
      <contact selfcollide="none"/>
      <elasticity young="{young_pa}" poisson="0.3" thickness="{thickness_m}" damping="0.002" elastic2d="both"/>
    </flexcomp>
  </worldbody>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    elem = model.flex_elem[: model.flex_elemnum[0] * 3].reshape(-1, 3)

    def vol(x):
        a, b, c = x[elem[:, 0]], x[elem[:, 1]], x[elem[:, 2]]
        return float(np.einsum("ij,ij->i", a - x.mean(0), np.cross(b - x.mean(0), c - x.mean(0))).sum() / 6.0)

    v0 = vol(data.flexvert_xpos.copy())
    nstep = int(round(duration_s / timestep_s))
    t0 = time.perf_counter()
    for _ in range(nstep):
        mujoco.mj_step(model, data)
    wall = time.perf_counter() - t0
    if sum(int(w.number) for w in data.warning):
        raise RigidError("flex sphere: MuJoCo reported a blow-up and reset the simulation; "
                         "expected a stable run (lower the time step or the stiffness)")
    return {"nvert": int(model.nflexvert), "us_per_step": wall / nstep * 1e6,
            "volume_change": (vol(data.flexvert_xpos.copy()) - v0) / v0}
