"""Compiled kinematics of attachment sites on rigid bodies, on MuJoCo's raw `MjData`
arrays, without MuJoCo itself: the wrench of point forces on their bodies and the
sites' velocities. `hybrid.rigid` uses them between steps and the step loop
(`hybrid.loop`) inside its compiled steps; neither needs MuJoCo loaded to compile.

Units: SI (m, s, N, N m). Arrays: `(n, 3)` float64, world frame.
"""

from __future__ import annotations

from .kernel import jit

__all__ = ["point_wrench_kernel", "add_point_wrench_kernel", "add_wrench_at", "site_vel_kernel"]


@jit(_nrt=False, inline="always")
def _site_offset(site_xpos, s, origin, c):  # pragma: no cover
    """site_xpos[s] - origin[c] as three floats (m): the lever arm of a site about a point.
    # Model: none   # Data in: site_xpos (nsite, 3) m, s, origin (n, 3) m, c   # Data out: returns (x, y, z) m
    """
    return site_xpos[s, 0] - origin[c, 0], site_xpos[s, 1] - origin[c, 1], site_xpos[s, 2] - origin[c, 2]


@jit(_nrt=False, inline="always")
def _add_wrench(site_xpos, xipos, s, b, fx, fy, fz, xfrc):  # pragma: no cover
    """xfrc[b] += [F, (site_xpos_s - xipos_b) x F], F = (fx, fy, fz) N at site s.
    # Model: none   # Data in: site_xpos (nsite, 3) m, xipos (nbody, 3) m   # Data out: xfrc[b] [N, N m]
    """
    add_wrench_at(site_xpos, s, xipos, b, fx, fy, fz, xfrc)


@jit(_nrt=False, inline="always")
def add_wrench_at(points, s, xipos, b, fx, fy, fz, xfrc):  # pragma: no cover
    """xfrc[b] += [F, (points_s - xipos_b) x F], F = (fx, fy, fz) N at point s of points.
    # Model: none   # Data in: points (n, 3) m, xipos (nbody, 3) m   # Data out: xfrc[b] [N, N m]
    """
    rx, ry, rz = _site_offset(points, s, xipos, b)
    xfrc[b, 0] += fx
    xfrc[b, 1] += fy
    xfrc[b, 2] += fz
    xfrc[b, 3] += ry * fz - rz * fy
    xfrc[b, 4] += rz * fx - rx * fz
    xfrc[b, 5] += rx * fy - ry * fx


@jit(_nrt=False)
def point_wrench_kernel(site_xpos, xipos, site_id, site_body, forces, xfrc):  # pragma: no cover
    """Set the wrench of the point forces on each attachment body (compiled).

    # Data in:  site_xpos (nsite, 3) m, xipos (nbody, 3) m, forces (n, 3) N
    # Model:    site_id (n,) int, site_body (n,) int
    # Data out: xfrc (nbody, 6) [N, N m]: rows site_body replaced by
    #           sum_i [F_i, (site_xpos_i - xipos_b) x F_i]; other rows untouched.
    """
    n = site_id.shape[0]
    for i in range(n):
        b = site_body[i]
        for k in range(6):
            xfrc[b, k] = 0.0
    for i in range(n):
        _add_wrench(site_xpos, xipos, site_id[i], site_body[i], forces[i, 0], forces[i, 1], forces[i, 2], xfrc)


@jit(_nrt=False)
def add_point_wrench_kernel(site_xpos, xipos, site_id, site_body, scale, forces, xfrc):  # pragma: no cover
    """Add the wrench of the point forces scale_i F_i at their sites to their bodies (compiled).

    # Data in:  site_xpos (nsite, 3) m, xipos (nbody, 3) m, scale (n,), forces (n, 3) N
    # Model:    site_id (n,) int, site_body (n,) int
    # Data out: xfrc (nbody, 6) [N, N m]: rows site_body added sum_i s_i [F_i, (site_xpos_i - xipos_b) x F_i]
    """
    for i in range(site_id.shape[0]):
        k = scale[i]
        _add_wrench(
            site_xpos, xipos, site_id[i], site_body[i], k * forces[i, 0], k * forces[i, 1], k * forces[i, 2], xfrc
        )


@jit(_nrt=False)
def site_vel_kernel(site_xpos, cvel, subtree_com, site_id, site_body, site_root, out):  # pragma: no cover
    """World linear velocities of sites, as mj_objectVelocity(flg_local=0) (compiled).

    # Data in:  site_xpos (nsite, 3) m, cvel (nbody, 6) [rad/s, m/s], subtree_com (nbody, 3) m
    # Model:    site_id, site_body, site_root (n,) int (root = body_rootid of the body)
    # Data out: out (n, 3) m/s = v_c + w x (site_xpos - subtree_com[root])
    """
    for i in range(site_id.shape[0]):
        s = site_id[i]
        b = site_body[i]
        c = site_root[i]
        rx, ry, rz = _site_offset(site_xpos, s, subtree_com, c)
        wx, wy, wz = cvel[b, 0], cvel[b, 1], cvel[b, 2]
        out[i, 0] = cvel[b, 3] + wy * rz - wz * ry
        out[i, 1] = cvel[b, 4] + wz * rx - wx * rz
        out[i, 2] = cvel[b, 5] + wx * ry - wy * rx
