"""MuJoCo alone, the references `hybrid bench` times our step against: bare
`mj_step` calls on an MJCF, and MuJoCo's own closed 2D flex sphere (an elastic
shell without a volume constraint). Each returns a stepper; the timing is the
benchmark's (hybrid.bench)."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from hybrid.errors import RigidError

from .mjcf import compile_spec, load_spec


class BareStepper:
    """`mj_step` from Python on the MJCF at `path`, from its reset state each call."""

    def __init__(self, path: str | Path):
        self.model = compile_spec(load_spec(path))
        self.data = mujoco.MjData(self.model)
        mujoco.mj_step(self.model, self.data)

    def reset(self) -> None:
        mujoco.mj_resetData(self.model, self.data)

    def step(self, nstep: int) -> None:
        model, data = self.model, self.data
        for _ in range(nstep):
            mujoco.mj_step(model, data)


class FlexSphere:
    """MuJoCo's own closed 2D flex sphere (elastic shell) resting on a plane under gravity.

    vert_pos (n, 3) m around the origin, face_vert (nface, 3) outward; `step(n)`
    advances n steps of `timestep_s`; `volume_change()` is the relative change of
    the enclosed volume since the start (MuJoCo has no volume constraint). `step`
    raises RigidError if MuJoCo reset the simulation (a blow-up).
    """

    def __init__(
        self,
        vert_pos: np.ndarray,
        face_vert: np.ndarray,
        *,
        total_kg: float = 4.0,
        young_pa: float = 3e4,
        thickness_m: float = 0.01,
        timestep_s: float = 1e-3,
    ):
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
        self.timestep_s = timestep_s
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        self._elem = self.model.flex_elem[: self.model.flex_elemnum[0] * 3].reshape(-1, 3)
        self._v0 = self._volume()

    @property
    def nvert(self) -> int:
        return int(self.model.nflexvert)

    def _volume(self) -> float:
        x = self.data.flexvert_xpos.copy()
        a, b, c = x[self._elem[:, 0]], x[self._elem[:, 1]], x[self._elem[:, 2]]
        o = x.mean(0)
        return float(np.einsum("ij,ij->i", a - o, np.cross(b - o, c - o)).sum() / 6.0)

    def step(self, nstep: int) -> None:
        model, data = self.model, self.data
        for _ in range(nstep):
            mujoco.mj_step(model, data)
        if sum(int(w.number) for w in data.warning):
            raise RigidError(
                "flex sphere: MuJoCo reported a blow-up and reset the simulation; "
                "expected a stable run (lower the time step or the stiffness)"
            )

    def volume_change(self) -> float:
        return (self._volume() - self._v0) / self._v0
