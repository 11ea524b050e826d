"""The one compiled step loop: the membrane alone, or coupled to MuJoCo's rigid bodies
(paper 3.5). Every run steps through `run_steps`: by steps (one stop) or by frames,
with or without a rigid part, with the scene's schedules or the user's controls.

One step, from time t:
1. the membrane's forces at t (`hybrid.step.membrane_forces`: only the terms the model has);
2. with a rigid part (`rig.coupled`): every linked point's membrane force, plus the
   pressure force of the last volume projection p grad_i V (how the incompressible
   abdomen pushes on the ribs), plus its weight correction, goes to its body as a
   wrench at its site (`xfrc_applied`); the driven actuators take their controls
   (`mjData.ctrl`); MuJoCo steps (`mj_step2` then `mj_step1`, or `mj_step` + `mj_step1`
   for RK4, so that the site kinematics belong to the new state; bit for bit
   `mj_step`; with lungs whose wall the bodies carry, their load made implicit in the
   bodies' velocities between the two, `hybrid.wall_coupling`); the linked points take
   their sites' positions and velocities;
3. the free points integrate, the local constraints and the exact volume projection
   apply, the divergence check runs (`hybrid.step.membrane_advance`); while the airway is
   occluded, the lungs' hold is then shared with the bodies that carry the cavity (MuJoCo's
   step taken again, the projection again: `hybrid.wall_coupling.hold_with_bodies`).

One compiled loop for every scene: which terms a model has, its integrator and whether
it has a rigid part are read at run time (`MembraneArrays.term_on`, `.integrator`,
`RigidPack.coupled`), never specialised on, so that a scene with another set of terms
loads the loop from the cache instead of compiling it again. Only the multi-core build is
an argument that prunes (`par`): a model too small for it never compiles it.

MuJoCo stays behind its door: the loop calls MuJoCo's C step functions through the
addresses `hybrid.coupling` puts in the pack (`MjViews.fn_step`, ...), so the compiled
code names no MuJoCo symbol, and a membrane-only scene passes an empty pack
(`membrane_only`): it never loads MuJoCo.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .calls import ADDRESS_ONLY, args_from_memory, args_in_memory, args_type_of, call_at, call_c
from .kernel import kernel
from .schedule import schedule_eval, stack_schedules
from .sites import add_point_wrench_kernel, add_wrench_at, point_wrench_kernel
from .step import (
    F_AIRWAY,
    F_ALVEOLAR,
    F_FLOW,
    F_KE,
    F_LUNG_VOLUME,
    F_PLEURAL,
    F_PRESSURE,
    F_TIME,
    F_VOLUME,
    OK,
    S_ORIGIN,
    S_PRESSURE,
    S_TIME,
    FrameColumn,
    membrane_advance,
    membrane_forces,
)
from .step_work import CALL_HOLD, CALL_RIGID, CALL_STEPS, CALL_STEPS_PARALLEL, CALL_WALL
from .terms import Lungs
from .terms.lung_cavity import cavity_volume_rate
from .terms.lungs import L_AIRWAY, L_ALVEOLAR, L_HOLD, L_OCCLUDED, L_PLEURAL, L_VOLUME, P_REF
from .terms.slide_planes import carry_planes
from .terms.volume import face_volume
from .wall_coupling import points_onto_sites

__all__ = [
    "LinkArrays",
    "WallArrays",
    "SlideArrays",
    "CtrlArrays",
    "MjViews",
    "WrenchHistory",
    "RigidPack",
    "FrameArrays",
    "Frames",
    "capture_frame",
    "kinetic_energy_of",
    "run_steps",
    "membrane_only",
    "steps_between",
    "rigid_between",
]

LUNGS_ID = Lungs.id


class LinkArrays(NamedTuple):
    """The n linked points and their attachment sites, in site order.

    Read: vert (n,) int32, the linked membrane vertices; site_id (n,) int64, their
    MuJoCo sites; site_body (n,) int64, each site's body; site_root (n,) int64, the
    root body of its kinematic tree (for `cvel`); extra_force (n, 3) N, added to each
    point's force (the weight correction, `hybrid.coupling`).
    Scratch: force (n, 3) N, the forces sent to the sites; vel (n, 3) m/s, the
    sites' velocities.
    """

    vert: np.ndarray
    site_id: np.ndarray
    site_body: np.ndarray
    site_root: np.ndarray
    extra_force: np.ndarray
    force: np.ndarray
    vel: np.ndarray


class WallArrays(NamedTuple):
    """The lungs' wall points the rigid bodies carry (`hybrid.terms.lungs`), nc of them:
    point (nc,) int64, their index in the wall (`MembraneState.lung_wall_pos`); weight (nc,),
    the share of their site's displacement each follows (the rest stays at rest: a point between
    its rib and the cage's fixed top); rest (nc, 3) m; site_rest (nc, 3) m, where their sites
    start; site_id, site_body, site_root (nc,) int64, their sites on their bodies. The wall's
    pleural load reaches each body as weight x force at the site: the transpose of how the
    point follows it (virtual work), implicit in the bodies' velocities (`hybrid.wall_coupling`);
    damping (nv,) N m s/rad: MuJoCo's joint damping where its Euler step takes it implicitly, else 0;
    g_points (ng,): the cavity's rigid-borne points (its indices: the linked points on it, then the
    carried ones), g_site, g_body (ng,) int64 and g_weight (ng,) their sites, bodies and shares;
    spec (1,) int32: the parts of MuJoCo's state it saves.
    Scratch: force (nc, 3) N, their loads; vel (nc, 3) m/s, the sites' velocities; unit (nlinks +
    nc, 3), qfrc (nv,), a (nv,), dense (nv, nv), saved (MuJoCo's state before its step), applied
    (nv,): the implicit coupling's; force_q (nv,): its generalized force in the step (N, N m);
    wrench (nbody, 6): the same as each body's wrench (N; N m about its centre of mass at the
    step's start), after the step (`hybrid.loads`)."""

    point: np.ndarray
    weight: np.ndarray
    rest: np.ndarray
    site_rest: np.ndarray
    site_id: np.ndarray
    site_body: np.ndarray
    site_root: np.ndarray
    force: np.ndarray
    vel: np.ndarray
    damping: np.ndarray
    g_points: np.ndarray
    g_site: np.ndarray
    g_body: np.ndarray
    g_weight: np.ndarray
    spec: np.ndarray
    unit: np.ndarray
    wrench: np.ndarray
    qfrc: np.ndarray
    a: np.ndarray
    dense: np.ndarray
    force_q: np.ndarray
    saved: np.ndarray
    applied: np.ndarray


class SlideArrays(NamedTuple):
    """The ns sliding points (`RigidLink.slide_stiffness_n_per_m3`), each held to the plane
    of its site: the plane through the site, normal to the site's z axis (`site_xmat`).
    Read: vert (ns,) int32, the membrane points; site_id, site_body (ns,) int64;
    stiffness (ns,) N/m. Scratch: force (ns, 3) N, the planes' forces on the points in the
    last step (their bodies took the opposite)."""

    vert: np.ndarray
    site_id: np.ndarray
    site_body: np.ndarray
    stiffness: np.ndarray
    force: np.ndarray


class CtrlArrays(NamedTuple):
    """The actuators a scene drives (`rigid.ctrl`): act (nc,) int64, their ids;
    sched, their schedules (`hybrid.schedule.ScheduleTable`, row j for act[j]);
    user (nc,) uint8: 1 where the user's program sets the actuator's `ctrl`
    (`hybrid.Control`), which the step then leaves as it is; scratch: val (3,)."""

    act: np.ndarray
    sched: object
    user: np.ndarray
    val: np.ndarray


class MjViews(NamedTuple):
    """MuJoCo's model and data as the compiled loop sees them: model_ptr, data_ptr
    (int), the `mjModel*` and `mjData*` for the C step functions; fn_step, fn_step1,
    fn_step2 (int): the addresses of `mj_step`, `mj_step1`, `mj_step2` of the library the
    bindings use (`hybrid.rigid.mj_step_ctypes`), fn_apply_ft, fn_full_m, fn_get_state, fn_set_state
    those of `mj_applyFT`, `mj_fullM`, `mj_getState`, `mj_setState` (`hybrid.wall_coupling`); and views of the
    `MjData`'s own arrays (valid as long as it lives), written by MuJoCo's step:
    site_xpos (nsite, 3) m; site_xmat (nsite, 9), the sites' orientations (row-major);
    xipos (nbody, 3) m, the bodies' centres of mass;
    xfrc_applied (nbody, 6) [N, N m]; cvel (nbody, 6) [rad/s, m/s]; subtree_com
    (nbody, 3) m; qpos (nq,); qvel (nv,); qfrc_applied (nv,); xpos (nbody, 3) m and xquat (nbody, 4) (w, x, y, z),
    the bodies' poses; ctrl (nu,), the actuators' controls."""

    model_ptr: int
    data_ptr: int
    fn_step: int
    fn_step1: int
    fn_step2: int
    fn_apply_ft: int
    fn_full_m: int
    fn_get_state: int
    fn_set_state: int
    site_xpos: np.ndarray
    site_xmat: np.ndarray
    xipos: np.ndarray
    xfrc_applied: np.ndarray
    cvel: np.ndarray
    subtree_com: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    qfrc_applied: np.ndarray
    xpos: np.ndarray
    xquat: np.ndarray
    ctrl: np.ndarray


class WrenchHistory(NamedTuple):
    """Per step k of a recorded run: xfrc (nstep, nbody, 6) [N, N m], the
    `xfrc_applied` used; qpos (nstep, nq), MuJoCo's qpos after the step; qfrc (nstep, nv),
    the generalized force of the lungs' implicit correction (`hybrid.wall_coupling`: as
    `qfrc_applied`, it gives the step MuJoCo took; 0 without it). Empty (nstep = 0) when not
    recording."""

    xfrc: np.ndarray
    qpos: np.ndarray
    qfrc: np.ndarray


class RigidPack(NamedTuple):
    """The rigid half of a coupled loop (`hybrid.coupling.Coupling` makes it): coupled:
    bool, a rigid part to step (False: `membrane_only`, every array empty); links, ctrls,
    mj, wall, slides (above); rk4: bool, MuJoCo integrates with RK4 (step with `mj_step`);
    record: bool, keep each step's wrenches and qpos in hist."""

    coupled: bool
    links: LinkArrays
    ctrls: CtrlArrays
    mj: MjViews
    wall: WallArrays
    slides: SlideArrays
    rk4: bool
    record: bool
    hist: WrenchHistory


@kernel(inline="always")
def kinetic_energy_of(m, s):
    """0.5 sum m v^2 over the integrated points (J).
    # Model: m.vert_free, m.vert_mass   # Data in: s.vert_vel (m/s)   # Data out: returns J
    """
    ke = 0.0
    vel = s.vert_vel
    for i in range(vel.shape[0]):
        if m.vert_free[i] > 0:
            ke += m.vert_mass[i] * (vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1] + vel[i, 2] * vel[i, 2])
    return 0.5 * ke


@kernel(inline="always")
def capture_frame(m, s, pos_out, scal_out):
    """The state's positions and numbers (F_* columns) into one frame's rows.
    # Model: m.face_vert, m.vert_free, m.vert_mass, m.lung_*   # Data in: s.vert_pos, s.vert_vel, s.scal, s.lung
    # Data out: pos_out (nvert, 3) m, scal_out (`FrameColumn`)
    """
    pos = s.vert_pos
    for i in range(pos.shape[0]):
        for a in range(3):
            pos_out[i, a] = pos[i, a]
    scal_out[F_TIME] = s.scal[S_TIME]
    scal_out[F_VOLUME] = face_volume(m.face_vert, pos)
    scal_out[F_PRESSURE] = s.scal[S_PRESSURE]
    scal_out[F_KE] = kinetic_energy_of(m, s)
    if m.term_on[LUNGS_ID]:  # the cavity now; its flow over the last step; its pressures at that step's start
        vol, _ = cavity_volume_rate(m.lung_face, m.lung_par[P_REF:], pos, s.vert_vel, s.lung_wall_pos, s.lung_wall_vel)
        scal_out[F_LUNG_VOLUME] = vol
        scal_out[F_FLOW] = (vol - s.lung[L_VOLUME]) / m.dt
        scal_out[F_PLEURAL] = s.lung[L_PLEURAL]
        scal_out[F_ALVEOLAR] = s.lung[L_ALVEOLAR]
        scal_out[F_AIRWAY] = s.lung[L_AIRWAY]


class FrameArrays(NamedTuple):
    """Where the loop captures its frames, per frame i: pos[i] (nvert, 3) m; scal[i]
    (`hybrid.step.FrameColumn`); body_pos[i] (nbody - 1, 3) m and body_quat[i]
    (nbody - 1, 4) (w, x, y, z), the rigid bodies' poses, world excluded (empty
    without a rigid part)."""

    pos: np.ndarray
    scal: np.ndarray
    body_pos: np.ndarray
    body_quat: np.ndarray


class Frames:
    """Frames captured in one compiled call (`Simulation.step_frames`): per frame,
    pos (nvert, 3) m, scal (`hybrid.step.FrameColumn`: time, volume, pressure, kinetic energy,
    the lungs' volume, flow and pressures: pleural, alveolar, airway-opening), and the
    rigid bodies' poses body_pos (nbody, 3) m, body_quat (nbody, 4) (w, x, y, z),
    world excluded. `count`: the frames of the last call, also when it raised."""

    def arrays(self, first: int = 0):
        """The compiled loop's view of frames first, first + 1, ... (`hybrid.loop.FrameArrays`)."""
        return FrameArrays(self.pos[first:], self.scal[first:], self.body_pos[first:], self.body_quat[first:])

    def __init__(self, capacity: int, nvert: int, nbody: int = 0):
        self.pos = np.zeros((capacity, nvert, 3))
        self.scal = np.zeros((capacity, len(FrameColumn)))
        self.body_pos = np.zeros((capacity, nbody, 3))
        self.body_quat = np.zeros((capacity, nbody, 4))
        self.count = 0

    @property
    def capacity(self) -> int:
        return len(self.pos)


@kernel(inline="always")
def rigid_phase(m, s, w, planes, t, row, rig, args_at, args_type):
    """Step phase 2 (module docstring): forces to the sites, controls, MuJoCo's step,
    the linked points onto their sites. args_at, args_type: (m, s, w, planes, rig) in the
    caller's frame (`rigid_between`), for the lungs' step compiled apart
    (`hybrid.wall_coupling.wall_step_between`).
    # Model:    m (MembraneArrays); rig.links.vert, .site_id, .site_body, .site_root,
    #           .extra_force; rig.ctrls.act, .sched, .user; rig.rk4; rig.wall (the lungs' carried wall)
    # Data in:  w.vert_force, s.grad, s.scal[S_PRESSURE] (the last projection's), w.lung_wall_force;
    #           rig.mj: MuJoCo's state; t (s), the step's time; row: the step's row of rig.hist;
    #           s.lung (the compartment at the step's start: the wall's implicit coupling)
    # Data out: MuJoCo's state (through rig.mj.data_ptr), rig.mj.xfrc_applied,
    #           rig.mj.ctrl[rig.ctrls.act] (the rows the user does not set); the linked
    #           points' s.vert_pos, s.vert_vel; the carried wall's s.lung_wall_pos, s.lung_wall_vel;
    #           rig.hist.xfrc[row], .qpos[row] when rig.record; implicit Euler's planes (`SlidePlanes`, placed)
    # Scratch:  rig.links.force, .vel, rig.ctrls.val, rig.wall (its scratch)
    """
    links, ctrls, mj, hist = rig.links, rig.ctrls, rig.mj, rig.hist
    pos, vel, frc, grad = s.vert_pos, s.vert_vel, w.vert_force, s.grad
    link_vert, site_id, link_force = links.vert, links.site_id, links.force
    xfrc, qpos = mj.xfrc_applied, mj.qpos
    p = s.scal[S_PRESSURE]
    for j in range(link_vert.shape[0]):
        i = link_vert[j]
        for a in range(3):
            link_force[j, a] = frc[i, a] + p * grad[i, a] + links.extra_force[j, a]
    wall = rig.wall
    slides = rig.slides
    _zero_rows(wall.site_body, xfrc)  # a body the wall or sliding points alone load: its row rewritten each step
    _zero_rows(slides.site_body, xfrc)
    point_wrench_kernel(mj.site_xpos, mj.xipos, site_id, links.site_body, link_force, xfrc)
    if wall.point.shape[0]:  # the lungs' wall: its load added to the bodies that carry it
        _gather_rows(wall.point, w.lung_wall_force, wall.force)
        add_point_wrench_kernel(mj.site_xpos, mj.xipos, wall.site_id, wall.site_body, wall.weight, wall.force, xfrc)
    if slides.vert.shape[0]:
        slide_forces(slides, mj.site_xpos, mj.site_xmat, mj.xipos, pos, frc, xfrc)
    for j in range(ctrls.act.shape[0]):
        if not ctrls.user[j]:
            schedule_eval(ctrls.sched, j, t, ctrls.val)
            mj.ctrl[ctrls.act[j]] = ctrls.val[0]
    if rig.record:  # element-wise: a slice copy would allocate
        for b in range(xfrc.shape[0]):
            for a in range(6):
                hist.xfrc[row, b, a] = xfrc[b, a]
    wall.force_q[:] = 0.0  # the lungs' correction, when there is one (`hybrid.wall_coupling`)
    wall.wrench[:] = 0.0
    if rig.rk4:
        call_c(mj.fn_step, (mj.model_ptr, mj.data_ptr))
    elif wall.qfrc.shape[0]:  # with lungs: their load implicit in the bodies' velocities
        call_at(w.calls[CALL_WALL], None, (args_at, args_type))
    else:
        call_c(mj.fn_step2, (mj.model_ptr, mj.data_ptr))
    call_c(mj.fn_step1, (mj.model_ptr, mj.data_ptr))
    if rig.record:
        for a in range(qpos.shape[0]):
            hist.qpos[row, a] = qpos[a]
        for a in range(hist.qfrc.shape[1]):
            hist.qfrc[row, a] = wall.force_q[a] if wall.force_q.shape[0] else 0.0
    points_onto_sites(links, wall, mj, pos, vel, s.lung_wall_pos, s.lung_wall_vel)
    carry_planes(slides.site_id, mj.site_xpos, mj.site_xmat, planes)  # implicit Euler's: the planes it solves with


@kernel
def slide_forces(slides, site_xpos, site_xmat, xipos, pos, vert_force, xfrc):
    """Each sliding point held to its plane: gap g = (x - x_site) . n, n the site's z axis; the
    force -k g n on the point, and its reaction k g n on the body at the point itself (the line of
    action through the point along n: the virtual work of the pair is exact as the point slides).
    Under implicit Euler the point's force here is the step's readout only (`StepWork.vert_force`;
    its solve copied the explicit forces before and takes the plane's itself at the step's end:
    `hybrid.terms.slide_planes`), the body's reaction the force the last solve ended with.
    # Model: slides.vert, .site_id, .site_body, .stiffness
    # Data in: site_xpos (nsite, 3) m, site_xmat (nsite, 9), xipos (nbody, 3) m, pos (nvert, 3) m
    # Data out: vert_force (nvert, 3) N and xfrc (nbody, 6) [N, N m] (added to); slides.force (ns, 3) N
    """
    for j in range(slides.vert.shape[0]):
        i, sid, b = slides.vert[j], slides.site_id[j], slides.site_body[j]
        nx, ny, nz = site_xmat[sid, 2], site_xmat[sid, 5], site_xmat[sid, 8]
        dx, dy, dz = pos[i, 0] - site_xpos[sid, 0], pos[i, 1] - site_xpos[sid, 1], pos[i, 2] - site_xpos[sid, 2]
        f = -slides.stiffness[j] * (dx * nx + dy * ny + dz * nz)
        fx, fy, fz = f * nx, f * ny, f * nz
        slides.force[j, 0], slides.force[j, 1], slides.force[j, 2] = fx, fy, fz
        vert_force[i, 0] += fx
        vert_force[i, 1] += fy
        vert_force[i, 2] += fz
        add_wrench_at(pos, i, xipos, b, -fx, -fy, -fz, xfrc)


@kernel
def _zero_rows(rows, out):
    """out[rows[j]] = 0.
    # Model: rows (n,) int64   # Data in: none   # Data out: out (m, k)
    """
    for j in range(rows.shape[0]):
        for a in range(out.shape[1]):
            out[rows[j], a] = 0.0


@kernel
def _gather_rows(rows, src, out):
    """out[j] = src[rows[j]].
    # Model: rows (n,) int64   # Data in: src (m, 3)   # Data out: out (n, 3)
    """
    for j in range(rows.shape[0]):
        for a in range(3):
            out[j, a] = src[rows[j], a]


@kernel
def run_steps(m, s, w, imp, c, stops, step0, frames, rig, par=True):
    """Steps (module docstring) to each step index of stops, capturing a frame at each
    (a stop at the current step captures it without stepping). Returns the frames
    captured: fewer than stops when a step fails, its status then in s.status
    (s.status[1]: the failing step's index). Step k runs from t = origin + k h: the
    same times however a run is cut into calls (a checkpoint, frames, timed pieces).
    The steps between two stops run in `steps_between`, compiled apart and called at its
    address (`StepWork.calls`), which reads the arrays from this call's frame.
    # Model:    m (MembraneArrays); rig (RigidPack): the rigid part, or `membrane_only`'s empty pack
    # Data in:  s (MembraneState) at step step0; c (ControlArrays): the inputs;
    #           w (StepWork): the step's work arrays; imp (ImplicitWork): implicit Euler's
    #           (empty for the explicit integrators);
    #           stops (nframe,) int64 increasing step indices from step0
    # Data out: s, c.value and c.value_next (the scheduled rows), MuJoCo's state after the steps done;
    #           frames (FrameArrays): frame i at stops[i]
    # par:      None: the membrane's serial passes only (`hybrid.step.step_par`)
    """
    args = (m, s, w, imp, c, rig)
    args_at, args_type = args_in_memory(args), args_type_of(args)
    done = step0
    if par is None:  # the two builds of `steps_between`, each compiled for its `par`
        steps_at = w.calls[CALL_STEPS]
    else:
        steps_at = w.calls[CALL_STEPS_PARALLEL]
    for f in range(stops.shape[0]):
        if call_at(steps_at, OK, (args_at, done, stops[f], step0, par, args_type)) != OK:
            return f
        done = stops[f]
        capture_frame(m, s, frames.pos[f], frames.scal[f])
        if rig.coupled:
            for b in range(frames.body_pos.shape[1]):
                for a in range(3):
                    frames.body_pos[f, b, a] = rig.mj.xpos[b + 1, a]
                for a in range(4):
                    frames.body_quat[f, b, a] = rig.mj.xquat[b + 1, a]
    return stops.shape[0]


@kernel(**ADDRESS_ONLY)
def steps_between(args_at, first, last, step0, par, args_type):
    """Steps first .. last - 1 (module docstring), the arrays (m, s, w, imp, c, rig) read from
    `run_steps`'s frame (`hybrid.kernel.args_in_memory`); with a rigid part, its phase called
    at its address (`rigid_between`). Returns a status code: OK, or the failing step's
    (its index in s.status[1]).
    # Model:    m (MembraneArrays), rig (RigidPack)   # Data in: args_at (int64), first, last,
    #           step0 (the first step of `run_steps`'s call: rig.hist's row 0), par, args_type
    # Data out: as `run_steps`, without its frames
    """
    m, s, w = (
        args_from_memory(args_at, 0, args_type),
        args_from_memory(args_at, 1, args_type),
        args_from_memory(args_at, 2, args_type),
    )
    imp, c, rig = (
        args_from_memory(args_at, 3, args_type),
        args_from_memory(args_at, 4, args_type),
        args_from_memory(args_at, 5, args_type),
    )
    rigid_args = (m, s, w, imp.planes, rig)
    rigid_at, rigid_type = args_in_memory(rigid_args), args_type_of(rigid_args)
    h = m.dt
    origin = s.scal[S_ORIGIN]
    for k in range(first, last):
        t = origin + k * h
        membrane_forces(m, s, w, imp, c, t, par)
        hold_before = s.lung[L_HOLD]  # the occluded airway's pressure the bodies take in this step
        if rig.coupled:
            call_at(w.calls[CALL_RIGID], None, (rigid_at, t, k - step0, rigid_type))
        code = membrane_advance(m, s, w, imp, c, t, k, par)
        if code != OK:
            return code
        if rig.coupled and not rig.rk4 and s.lung[L_OCCLUDED] != 0.0 and w.calls[CALL_HOLD] != 0:  # shared
            code = call_at(w.calls[CALL_HOLD], OK, (rigid_at, k, k - step0, hold_before, rigid_type))
            if code != OK:
                return code
        s.scal[S_TIME] = origin + (k + 1) * h
    return OK


@kernel(**ADDRESS_ONLY)
def rigid_between(args_at, t, row, args_type):
    """`rigid_phase`, its arrays (m, s, w, planes, rig) read from `steps_between`'s frame: the
    phase that step calls at its address (`StepWork.calls`), compiled for scenes with a rigid part.
    # Model: m, rig   # Data in: args_at (int64), t (s), row, args_type   # Data out: as `rigid_phase`
    """
    m, s, w = (
        args_from_memory(args_at, 0, args_type),
        args_from_memory(args_at, 1, args_type),
        args_from_memory(args_at, 2, args_type),
    )
    planes, rig = args_from_memory(args_at, 3, args_type), args_from_memory(args_at, 4, args_type)
    rigid_phase(m, s, w, planes, t, row, rig, args_at, args_type)


def membrane_only() -> RigidPack:
    """The pack of a scene without a rigid part: `coupled` False, every array empty, no
    MuJoCo (the loop never reads it)."""
    i64, f3 = np.zeros(0, np.int64), np.zeros((0, 3))
    # read-only as a rigid part's (`hybrid.rigid.CoupledRigid`): the same types, the same compiled loop
    fixed = _read_only(np.zeros(0, np.int64))
    fixed_i32, fixed_f = _read_only(np.zeros(0, np.int32)), _read_only(np.zeros(0))
    links = LinkArrays(fixed_i32, fixed, fixed, fixed, f3, f3, f3)
    ctrls = CtrlArrays(fixed, stack_schedules(())[0], np.zeros(0, np.uint8), np.zeros(3))
    f6, f9 = np.zeros((0, 6)), np.zeros((0, 9))
    f0, f00 = np.zeros(0), np.zeros((0, 0))
    mj = MjViews(0, 0, 0, 0, 0, 0, 0, 0, 0, f3, f9, f3, f6, f6, f3, f0, f0, f0, f3, np.zeros((0, 4)), f0)
    i32 = np.zeros(1, np.int32)
    # read-only where the rigid part's are (`hybrid.rigid.RigidSystem`): the same types, the same loop
    wall = WallArrays(
        point=i64,
        weight=f0,
        rest=f3,
        site_rest=f3,
        site_id=fixed,
        site_body=fixed,
        site_root=fixed,
        force=f3,
        vel=f3,
        damping=f0,
        g_points=i64,
        g_site=fixed,
        g_body=fixed,
        g_weight=f0,
        spec=i32,
        unit=f3,
        wrench=f6,
        qfrc=f0,
        a=f0,
        dense=f00,
        force_q=f0,
        saved=f0,
        applied=f0,
    )
    slides = SlideArrays(fixed_i32, fixed, fixed, fixed_f, f3)
    hist = WrenchHistory(np.zeros((0, 0, 6)), np.zeros((0, 0)), np.zeros((0, 0)))
    return RigidPack(False, links, ctrls, mj, wall, slides, False, False, hist)


def _read_only(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a
