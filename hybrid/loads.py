"""The loads the membrane puts on the skeleton (docs/outputs.md, "Loads on the skeleton"; docs/metrics.md).

For each body the membrane is linked to, and each nailed region, the net force (N)
and moment (N m) the membrane applies to it, and the moment of the intra-abdominal
pressure about named joints (`rigid.load_joints`). Read from a `Simulation` after a
step (an observer: never inside the step, nothing changed):

- a linked body receives, each step, the forces `hybrid.coupling` sends to its
  attachment sites: each linked point's membrane force plus the volume projection's
  pressure force p grad_i V (`Coupling.link_forces`), without the correction for
  the linked point's own weight (that weight is on the body's mass, not a load of
  the membrane);
- a body that sliding points lean on (`RigidLink.slide_stiffness_n_per_m3`) receives the
  opposite of each plane's force on its point, at the point (`Coupling.slide_forces`);
- a body that carries the lungs' wall (`hybrid.terms.lungs`) receives each carried point's
  pleural load times its share, at the point's site (`Coupling.wall_forces`), and every body
  the thoracic cavity moves with receives the step's implicit correction of that load
  (`hybrid.wall_coupling`) as a wrench at its centre of mass (`Coupling.wall_correction_wrenches`):
  with the linked points' forces (which hold the pleural load on the dome's border) these are
  the lungs' whole load on the skeleton, exactly what MuJoCo applied;
- a nailed region receives what its nail holds: the forces on its points that the
  nail cancels, each point's membrane force of the last step plus, under the exact
  volume constraint, p grad_i V of the last projection; the nail's reaction is minus
  this;
- the intra-abdominal pressure's moment about a point c is the sum over the points
  the skeleton holds (linked and nailed) of (x_i - c) x p grad_i V(x), V's gradient
  at the current positions. Over the whole closed surface this sum is zero (V is
  invariant under rotations): the pressure's moment on the skeleton is that of the
  pressure on the held points, which the free membrane's tension balances.

Every moment is M = sum (x_i - c) x F_i, in the scene's frame (right-handed, the
moment's vector along the axis the load turns the body about, counter-clockwise
seen from its tip); c is the body's origin (MuJoCo's `xpos`, now), a nailed region's
rest centroid, or a named joint's anchor (MuJoCo's `xanchor`, now). The arms are
the points' positions after the step whose forces are given (a wall point's: its site's; the
correction's: the body's centre of mass, MuJoCo's `xipos`).
"""

from __future__ import annotations

import numpy as np

from .mesh.geometry import cross_rows, volume_gradient
from .regions import select
from .step import S_PRESSURE
from .terms import Nailed, Volume

__all__ = ["Loads", "LoadGroup", "LoadsObserver", "topics"]


class LoadGroup:
    """The points whose forces one part of the skeleton takes: kind "body" (a linked
    body: rows, its rows in the coupling's link order, then slide_rows, its sliding points,
    then wall_rows, the lungs' carried wall points on it) or "nail" (a nailed region)."""

    def __init__(
        self,
        kind: str,
        name: str,
        vert: np.ndarray,
        rows: np.ndarray | None = None,
        body_id: int = -1,
        centre_m: np.ndarray | None = None,
    ):
        self.kind, self.name, self.vert, self.rows = kind, name, vert, rows
        self.slide_rows = np.zeros(0, np.int64)  # a body's sliding points, in `slide_vert` order, after rows
        self.wall_rows = np.zeros(0, np.int64)  # the lungs' wall points it carries, in `wall_point` order
        self.body_id, self.centre_m = body_id, centre_m

    @property
    def label(self) -> str:
        return f"{self.kind}/{self.name}"

    def about(self) -> str:
        """The point its moment is taken about, in words."""
        if self.kind == "body":
            return "the body's origin (MuJoCo xpos)"
        return f"the region's rest centroid {np.round(self.centre_m, 6).tolist()} m"


class Loads:
    """The loads of a simulation's skeleton (module docstring). `groups`: the linked
    bodies, then the nailed regions; `joints`: the named joints' (name, id).
    `sample()` gives the current figures; `channels()` their names."""

    def __init__(self, sim):
        self.sim = sim
        model = sim.model
        self.exact_volume = bool(model.arrays.term_on[Volume.id])
        self.groups: list[LoadGroup] = []
        self.joints: list[tuple[str, int]] = []
        held = []  # the points the skeleton holds (linked and nailed; a sliding point is free)
        if sim.rigid is not None:
            system = sim.rigid.system
            site_body = np.asarray(system.site_body)
            slide_body = np.asarray(system.slide_site_body)
            wall_body = np.asarray(system.wall_site_body)
            for b in dict.fromkeys([*site_body.tolist(), *slide_body.tolist(), *wall_body.tolist()]):
                rows, slide_rows = np.nonzero(site_body == b)[0], np.nonzero(slide_body == b)[0]
                name = sim.mj_model.body(b).name or f"body{b}"
                vert = np.concatenate([sim.rigid.link_vert[rows], system.slide_vert[slide_rows]]).astype(np.int64)
                group = LoadGroup("body", name, vert, rows, body_id=int(b))
                group.slide_rows, group.wall_rows = slide_rows, np.nonzero(wall_body == b)[0]
                self.groups.append(group)
                held.append(sim.rigid.link_vert[rows])
            self.joints = [(n, int(sim.mj_model.joint(n).id)) for n in system.controls.load_joints]
        rest = model.mesh.vert_pos
        for _k, term in enumerate(model.scene.constraints):
            if isinstance(term, Nailed):
                idx = (
                    model.regions[term.region]
                    if isinstance(term.region, str) and term.region in model.regions
                    else select(
                        term.region, rest, name=term.name, regions=model.regions, face_vert=model.mesh.face_vert
                    )
                )
                idx = np.asarray(idx, np.int64)
                self.groups.append(LoadGroup("nail", term.name, idx, centre_m=rest[idx].mean(axis=0)))
                held.append(idx)
        self.held = np.unique(np.concatenate(held)).astype(np.int64) if held else np.zeros(0, np.int64)
        self.closed = bool(model.mesh.closed)
        # the faces round the held points: their fans give V's gradient there (a closed fan's
        # sum does not depend on the origin), at a fraction of the whole surface's cost
        touches = np.zeros(model.nvert, bool)
        touches[self.held] = True
        fans = model.mesh.face_vert[touches[model.mesh.face_vert].any(axis=1)]
        self._fan_vert, fans_local = np.unique(fans, return_inverse=True)  # the fans' points, numbered anew
        self._fans = fans_local.reshape(fans.shape)
        self._held_in_fans = np.searchsorted(self._fan_vert, self.held)
        # the linked points' weight correction, a constant of the model (`Coupling.link_extra_force`)
        self._extra = sim.rigid.link_extra_force() if sim.rigid is not None else None

    def __bool__(self) -> bool:
        return bool(self.groups)

    def channels(self) -> list[str]:
        """The names of `sample()`'s rows: per group GROUP/force_n, GROUP/moment_n_m and
        GROUP/moment_about/JOINT_n_m; under the exact volume constraint, iap/force_n and
        iap/moment_about/JOINT_n_m (GROUP: body/NAME or nail/NAME). The recording's
        channels are /loads/CHANNEL/x, /y, /z (`topics`)."""
        names = []
        for g in self.groups:
            names += [f"{g.label}/force_n", f"{g.label}/moment_n_m"]
            names += [f"{g.label}/moment_about/{j}_n_m" for j, _ in self.joints]
        if self._has_pressure():
            names += ["iap/force_n"] + [f"iap/moment_about/{j}_n_m" for j, _ in self.joints]
        return names

    def _has_pressure(self) -> bool:
        return self.closed and self.held.size > 0 and self.exact_volume

    def point_forces(self) -> dict:
        """{group label: (n, 3) N}, the forces each group's points apply to it now (`point_loads`
        without where they act)."""
        return {label: f for label, (_, f) in self.point_loads().items()}

    def point_loads(self) -> dict:
        """{group label: (x (n, 3) m, f (n, 3) N)}, the forces each group's points apply to it
        now and where: a linked or sliding point's at the point, a carried wall point's (its
        share of the pleural load) at its site."""
        s = self.sim.state
        p = float(s.scal[S_PRESSURE])
        pos = s.vert_pos
        out = {}
        link_force = slide_force = wall_force = None
        for g in self.groups:
            if g.kind == "body":
                if link_force is None:
                    rigid = self.sim.rigid
                    link_force = rigid.link_forces() - self._extra
                    slide_force = rigid.slide_forces()
                    wall_force = rigid.wall_forces() * rigid.system.wall_weight[:, None]
                    wall_at = self.sim.mj_data.site_xpos[rigid.system.wall_site_id]
                # a sliding point loads its body with the opposite of its plane's force on it
                f = np.concatenate([link_force[g.rows], -slide_force[g.slide_rows], wall_force[g.wall_rows]])
                out[g.label] = (np.concatenate([pos[g.vert], wall_at[g.wall_rows]]), f)
            else:
                f = np.array(self.sim.work.vert_force[g.vert])
                if self.exact_volume:
                    f += p * s.grad[g.vert]
                out[g.label] = (pos[g.vert], f)
        return out

    def anchors(self) -> np.ndarray:
        """(njoint, 3) m: the named joints' anchors now."""
        d = self.sim.mj_data
        return np.array([d.xanchor[j] for _, j in self.joints]).reshape(-1, 3)

    def iap_forces(self) -> np.ndarray:
        """(nheld, 3) N: p grad_i V at the held points (`held`), at the current positions."""
        pos = self.sim.state.vert_pos
        grad = volume_gradient(pos[self._fan_vert], self._fans)
        return float(self.sim.state.scal[S_PRESSURE]) * grad[self._held_in_fans]

    def sample(self) -> np.ndarray:
        """(len(channels()), 3): the current figures, in `channels()`'s order."""
        pos = self.sim.state.vert_pos
        loads = self.point_loads()
        anchors = self.anchors()
        rigid = self.sim.rigid
        if rigid is not None:
            xpos, xipos = self.sim.mj_data.xpos, self.sim.mj_data.xipos
            correction = rigid.wall_correction_wrenches()
        rows = []
        for g in self.groups:
            about = np.vstack([xpos[g.body_id] if g.kind == "body" else g.centre_m, anchors])
            x, f = loads[g.label]
            net, moments = _net_and_moments(x, f, about)
            if g.kind == "body":  # the lungs' correction: a force at its centre of mass and a torque
                w = correction[g.body_id]
                more, more_moments = _net_and_moments(xipos[g.body_id][None], w[None, :3], about)
                net, moments = net + more, moments + more_moments + w[3:]
            rows += [net, moments]
        if self._has_pressure():
            rows += [*_net_and_moments(pos[self.held], self.iap_forces(), anchors)]
        return np.concatenate(rows).reshape(-1, 3)

    def about(self) -> dict:
        """{group label or "iap": the point its moments are taken about, in words}."""
        out = {g.label: g.about() for g in self.groups}
        for name, _ in self.joints:
            out[f"moment_about/{name}"] = f"joint {name!r}'s anchor (MuJoCo xanchor)"
        return out


def _net_and_moments(x: np.ndarray, f: np.ndarray, about: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The net force (1, 3) N of forces f at points x, and their moments (n, 3) N m about
    the points `about` (n, 3): sum (x_i - c) x f_i = sum x_i x f_i - c x (the net force)."""
    net = f.sum(axis=0, keepdims=True)
    return net, cross_rows(x, f).sum(axis=0) - cross_rows(about, np.broadcast_to(net, about.shape))


def topics(names: list[str]) -> list[str]:
    """The recording's topics of the channels `names`, three a channel (x, y, z)."""
    return [f"/loads/{name}/{axis}" for name in names for axis in "xyz"]


class LoadsObserver:
    """A `hybrid.run` observer keeping the loads' range over the run: per channel the
    componentwise min and max and the largest norm (frames after the first step).
    `current(sim)` gives the figures of sim's step, sampled once (the recorder's too)."""

    def __init__(self, loads: Loads):
        self.loads = loads
        self.names = loads.channels()
        n = len(self.names)
        self.lo = np.full((n, 3), np.inf)
        self.hi = np.full((n, 3), -np.inf)
        self.norm_max = np.zeros(n)
        self.t: list[float] = []
        self.rows: list[np.ndarray] = []
        self.keep = False
        self._step = self._counted = -1
        self._last = None

    def current(self, sim) -> np.ndarray | None:
        """The figures at sim's current step (sampled once a step), None before the first."""
        if sim.steps_done == 0:  # no step yet: no force has been transferred
            return None
        if sim.steps_done != self._step:
            self._step, self._last = sim.steps_done, self.loads.sample()
        return self._last

    def __call__(self, sim, trace=None) -> None:
        if sim.steps_done == 0 or sim.steps_done == self._counted:
            return
        self._counted = sim.steps_done
        v = self.current(sim)
        np.minimum(self.lo, v, out=self.lo)
        np.maximum(self.hi, v, out=self.hi)
        np.maximum(self.norm_max, np.linalg.norm(v, axis=1), out=self.norm_max)
        if self.keep:
            self.t.append(sim.time)
            self.rows.append(v)

    def summary(self) -> dict:
        """{"about": ..., CHANNEL: {"min": [x, y, z], "max": [x, y, z], "norm_max": |v|}}."""
        out = {"about": self.loads.about()}
        if not np.isfinite(self.lo).all():
            return out
        for k, name in enumerate(self.names):
            out[name] = {"min": self.lo[k].tolist(), "max": self.hi[k].tolist(), "norm_max": float(self.norm_max[k])}
        return out
