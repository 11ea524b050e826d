"""The compiled rigid system (hybrid.rigid.system): the trunk's hinged ribs against closed
forms, the wrench transfer from point forces, and the compiled site kernels.

Tolerances come from the integrator: the static test from the decay envelope of the
damped oscillator, the frequency test from the dispersion of semi-implicit Euler."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from helpers import RIBS

from hybrid import rigid
from hybrid.errors import RigidError


def trunk_system(
    *, sternum: bool = True, gravity: bool = True, damping: bool = True, spec: mujoco.MjSpec | None = None, sites=()
) -> rigid.RigidSystem:
    """The trunk model, optionally without the sternum spring, gravity or hinge damping."""
    system = rigid.RigidSystem(spec or rigid.load_spec(rigid.TRUNK_XML), sites)
    m = system.model
    if not sternum:
        m.tendon_stiffness[:] = 0.0
        m.tendon_damping[:] = 0.0
    if not gravity:
        m.opt.gravity[:] = 0.0
    if not damping:
        m.dof_damping[:] = 0.0
    system.forward()
    return system


def hinge_inertia(m: mujoco.MjModel, d: mujoco.MjData, body: str) -> float:
    """Moment of inertia (kg m^2) of a hinged body about its joint axis.

    Body inertia in its principal frame, rotated to the world, plus the parallel-axis
    term for the offset of the centre of mass from the axis.
    """
    b = m.body(body).id
    j = m.body_jntadr[b]
    axis = d.xaxis[j]
    rot = d.ximat[b].reshape(3, 3)
    inertia_com = rot @ np.diag(m.body_inertia[b]) @ rot.T
    r = d.xipos[b] - d.xanchor[j]
    inertia_anchor = inertia_com + m.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
    return float(axis @ inertia_anchor @ axis + m.dof_armature[m.jnt_dofadr[j]])


def test_positive_hinge_rotation_lifts_the_rib_fronts():
    system = trunk_system()
    d = system.data
    front = [system.model.site(f"{rib}_front").id for rib in RIBS]
    z0 = d.site_xpos[front, 2].copy()
    d.qpos[:] += 0.01
    system.forward()
    lift = d.site_xpos[front, 2] - z0
    # lever arm of the front about the hinge axis is about 0.23 m: lift ~ 2.3 mm
    assert np.all(lift > 2e-3) and np.all(lift < 3e-3)


def test_ribs_rest_at_zero_deflection_under_gravity():
    system = trunk_system()
    for _ in range(4000):
        system.step()
    # springref balances the ribs' weight: rest at qpos = 0 (to the rounding of springref)
    assert np.abs(system.data.qpos).max() < 1e-7
    assert np.abs(system.data.qvel).max() < 1e-9


def test_hinged_rib_under_constant_torque_settles_at_torque_over_stiffness():
    system = trunk_system(sternum=False, gravity=False)
    m, d = system.model, system.data
    torque = 0.12  # N m, about 10 mrad
    for rib in RIBS:
        b = m.body(rib).id
        d.xfrc_applied[b, 3:] = torque * d.xaxis[m.body_jntadr[b]]
    duration = 6.0
    for _ in range(int(duration / m.opt.timestep)):
        system.step()
    k = m.jnt_stiffness[0]
    h = m.opt.timestep
    inertia = hinge_inertia(m, d, "rib_left")
    zeta = m.dof_damping[0] / (2.0 * np.sqrt(k * inertia))
    # Euler with implicit damping shrinks the oscillation by sqrt(I / (I + h c)) per step
    # (about D / 2I per second); it starts from rest at springref, torque / k away.
    decay = np.log1p(h * m.dof_damping[0] / inertia) / (2.0 * h)
    envelope = torque / k * np.exp(-decay * duration) / np.sqrt(1.0 - zeta**2)
    tol = 10.0 * envelope + 1e-12  # 1e-12: round-off of the equilibrium (qpos ~ 0.03)
    assert tol < 2e-12
    deflection = d.qpos - m.qpos_spring
    np.testing.assert_allclose(deflection, torque / k, rtol=0, atol=tol)


def test_small_oscillation_frequency_matches_sqrt_k_over_inertia():
    system = trunk_system(sternum=False, gravity=False, damping=False)
    m, d = system.model, system.data
    h = m.opt.timestep
    amplitude = 1e-3
    d.qpos[:] = m.qpos_spring[:2] + amplitude
    system.forward()
    inertia = hinge_inertia(m, d, "rib_left")
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    assert inertia == pytest.approx(full[0, 0], rel=1e-12)  # parallel axis == MuJoCo's M
    omega = np.sqrt(m.jnt_stiffness[0] / inertia)

    nstep = 2000
    x = np.empty(nstep + 1)
    x[0] = d.qpos[0] - m.qpos_spring[0]
    for i in range(nstep):
        system.step()
        x[i + 1] = d.qpos[0] - m.qpos_spring[0]
    # upward zero crossings, linearly interpolated
    i = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    t_cross = (i + x[i] / (x[i] - x[i + 1])) * h
    period = (t_cross[-1] - t_cross[0]) / (len(t_cross) - 1)
    assert len(t_cross) >= 10
    measured = 2.0 * np.pi / period
    # semi-implicit Euler: omega_h = (2/h) asin(omega h / 2), relative error (omega h)^2/24
    assert measured == pytest.approx(omega, rel=1e-2)
    assert measured == pytest.approx(2.0 / h * np.arcsin(omega * h / 2.0), rel=1e-4)


def test_apply_point_forces_sums_the_wrenches_about_the_centre_of_mass():
    spec = rigid.load_spec(rigid.TRUNK_XML)
    m0 = spec.compile()
    d0 = mujoco.MjData(m0)
    mujoco.mj_kinematics(m0, d0)
    com = d0.xipos[m0.body("rib_left").id].copy()
    points = np.array([com + [0.1, 0.0, 0.0], com, [0.0, -0.104, 0.06]])
    names = rigid.attach_points(spec, ["rib_left", "rib_left", "rib_right"], points)
    system = rigid.RigidSystem(spec, names)
    forces = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 0.0], [0.0, 0.5, 0.0]])
    system.apply_point_forces(forces)
    xfrc = system.data.xfrc_applied
    left, right = system.model.body("rib_left").id, system.model.body("rib_right").id
    # by hand: (0.1, 0, 0) x (0, 0, 2) = (0, -0.2, 0); the force at the COM has no torque
    np.testing.assert_allclose(xfrc[left], [1.0, 0.0, 2.0, 0.0, -0.2, 0.0], atol=1e-15)
    r = points[2] - system.data.xipos[right]
    np.testing.assert_allclose(xfrc[right, :3], forces[2])
    np.testing.assert_allclose(xfrc[right, 3:], np.cross(r, forces[2]), atol=1e-15)
    assert not xfrc[system.model.body("spine").id].any()
    with pytest.raises(RigidError, match=r"forces: expected shape \(3, 3\)"):
        system.apply_point_forces(np.zeros((2, 3)))


def test_site_pos_and_vel_belong_to_the_state_after_the_step():
    spec = rigid.load_spec(rigid.TRUNK_XML)
    names = rigid.attach_points(spec, ["rib_left", "rib_right"], np.array([[0.05, 0.09, 0.06], [0.05, -0.09, 0.06]]))
    system = rigid.RigidSystem(spec, names)
    system.apply_point_forces(np.array([[0.0, 0.0, 3.0], [0.0, 1.0, -2.0]]))
    for _ in range(50):
        system.step()
    m, d = system.model, system.data
    check = mujoco.MjData(m)
    check.qpos[:], check.qvel[:] = d.qpos, d.qvel
    mujoco.mj_forward(m, check)
    np.testing.assert_array_equal(system.site_pos(), check.site_xpos[system.site_id])
    res = np.zeros(6)
    for i, sid in enumerate(system.site_id):
        mujoco.mj_objectVelocity(m, check, mujoco.mjtObj.mjOBJ_SITE, sid, res, 0)
        np.testing.assert_allclose(system.site_vel()[i], res[3:], rtol=0, atol=1e-14)
    assert np.abs(system.site_vel()).max() > 1e-3  # it does move
    system.reset()
    assert system.time == 0.0 and not system.data.qvel.any()


def test_numba_loop_calls_mujoco_bit_for_bit():
    numba = pytest.importorskip("numba")
    _, step1, step2 = rigid.mj_step_ctypes()

    @numba.njit
    def run(m_ptr, d_ptr, nstep, forces, site_xpos, xipos, site_id, site_body, xfrc, out):
        for k in range(nstep):
            rigid.point_wrench_kernel(site_xpos, xipos, site_id, site_body, forces[k], xfrc)
            step2(m_ptr, d_ptr)
            step1(m_ptr, d_ptr)
            out[k] = site_xpos[site_id[0], 2]

    spec = rigid.load_spec(rigid.TRUNK_XML)
    names = rigid.attach_points(spec, ["rib_left", "rib_right"], np.array([[0.05, 0.09, 0.06], [0.05, -0.09, 0.06]]))
    forces = np.random.default_rng(5).normal(size=(300, 2, 3))
    a, b = rigid.RigidSystem(spec, names), rigid.RigidSystem(spec, names)
    z = np.empty(300)
    for k in range(300):
        a.apply_point_forces(forces[k])
        a.step()
        z[k] = a.site_pos()[0, 2]
    d = b.data
    out = np.empty(300)
    run(*b.pointers(), 300, forces, d.site_xpos, d.xipos, b.site_id, b.site_body, d.xfrc_applied, out)
    np.testing.assert_array_equal(out, z)
    np.testing.assert_array_equal(d.qpos, a.data.qpos)
