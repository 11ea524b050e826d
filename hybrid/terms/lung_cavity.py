"""The thoracic cavity's volume, its rate and its gradient, and a pressure's load on its points
(`hybrid.terms.lungs`): kernels over a closed surface whose points are the membrane's (cavity
index i < nvert) and the wall's (index nvert + its row), so that the cavity stays closed however the
membrane and the rigid bodies that carry the wall move. Each face's six times gradient at its
corners a, b, c is b x c, c x a, a x b (positions relative to a reference point), the divergence
theorem's tetrahedra as the abdomen's volume (`hybrid.terms.volume`)."""

from __future__ import annotations

from ..kernel import kernel

__all__ = [
    "cavity_corner",
    "cavity_volume_rate",
    "cavity_volume_rate_gradient",
    "add_cavity_pressure",
    "add_cavity_load",
    "add_hold_pressure",
]


@kernel(inline="always")
def cavity_corner(i, nvert, pos, wall, ref):
    """Point i of the cavity relative to ref: a membrane point (i < nvert) or a wall point.
    # Model: wall (nwall, 3) m, ref (3,) m   # Data in: pos (nvert, 3) m   # Data out: returns (x, y, z) m
    """
    if i < nvert:
        return pos[i, 0] - ref[0], pos[i, 1] - ref[1], pos[i, 2] - ref[2]
    j = i - nvert
    return wall[j, 0] - ref[0], wall[j, 1] - ref[1], wall[j, 2] - ref[2]


@kernel(inline="always")
def _speed(i, nvert, vel, wall_vel):
    """Velocity of cavity point i: the membrane's or the wall's.
    # Model: none   # Data in: vel (nvert, 3) m/s, wall_vel (nwall, 3) m/s   # Data out: returns (vx, vy, vz) m/s
    """
    if i < nvert:
        return vel[i, 0], vel[i, 1], vel[i, 2]
    j = i - nvert
    return wall_vel[j, 0], wall_vel[j, 1], wall_vel[j, 2]


@kernel(inline="always")
def _face_volume_rate(face, f, nvert, pos, vel, wall, wall_vel, ref):
    """Face f's six times share of the cavity's volume and of its rate (the latter in two
    parts, summed in turn as the callers always have), and its corners' six times gradients.
    # Model: face (nf, 3) int64, ref (3,) m   # Data in: pos, vel, wall, wall_vel
    # Data out: returns (6 dV m^3, (6 dV/dt over a and b, over c) m^3/s, the corners' 6 g m^2)
    """
    a, b, c = face[f, 0], face[f, 1], face[f, 2]
    ax, ay, az = cavity_corner(a, nvert, pos, wall, ref)
    # b x c, c x a, a x b: 6 g at a, b, c
    corners = _face_gradients(face, f, nvert, pos, wall, ref)
    (gax, gay, gaz), (gbx, gby, gbz), (gcx, gcy, gcz) = corners
    vax, vay, vaz = _speed(a, nvert, vel, wall_vel)
    vbx, vby, vbz = _speed(b, nvert, vel, wall_vel)
    vcx, vcy, vcz = _speed(c, nvert, vel, wall_vel)
    rate_ab = vax * gax + vay * gay + vaz * gaz + vbx * gbx + vby * gby + vbz * gbz
    return ax * gax + ay * gay + az * gaz, (rate_ab, vcx * gcx + vcy * gcy + vcz * gcz), corners


@kernel
def cavity_volume_rate(face, ref, pos, vel, wall, wall_vel):
    """The cavity's volume (m^3) and its rate sum_i g_i . v_i (m^3/s), g = dV/dx.
    # Model: face (nf, 3) int64 (a point i >= nvert is wall point i - nvert), ref (3,) m
    # Data in: pos (nvert, 3) m, vel (nvert, 3) m/s, wall (nwall, 3) m, wall_vel (nwall, 3) m/s
    # Data out: returns (V, dV/dt)
    """
    return _volume_rate_pass(face, ref, pos, vel, wall, wall_vel, wall[:0])  # no rows: no gradients


@kernel(inline="always")
def _volume_rate_pass(face, ref, pos, vel, wall, wall_vel, grad6):
    """`cavity_volume_rate`, and each face's corners' six times gradients summed into grad6
    when it has rows (`cavity_volume_rate_gradient`; the rows zeroed before).
    # Model: face, ref   # Data in: pos, vel, wall, wall_vel   # Data out: returns (V, dV/dt); grad6
    """
    nvert = pos.shape[0]
    keep = grad6.shape[0] > 0
    vol = rate = 0.0
    for f in range(face.shape[0]):
        dvol, (drate_ab, drate_c), corners = _face_volume_rate(face, f, nvert, pos, vel, wall, wall_vel, ref)
        vol += dvol
        rate += drate_ab
        rate += drate_c
        if keep:
            for r in range(3):
                i = face[f, r]
                for d in range(3):
                    grad6[i, d] += corners[r][d]
    return vol / 6.0, rate / 6.0


@kernel(inline="always")
def _push(i, nvert, k, gx, gy, gz, vert_force, wall_force, to_points):
    """Add k g to cavity point i's force: the membrane's (added to, if to_points) or the wall's.
    # Model: none   # Data in: i, k, g   # Data out: vert_force (nvert, 3) N, wall_force (nwall, 3) N
    """
    if i < nvert:
        if not to_points:
            return
        vert_force[i, 0] += k * gx
        vert_force[i, 1] += k * gy
        vert_force[i, 2] += k * gz
    else:
        j = i - nvert
        wall_force[j, 0] += k * gx
        wall_force[j, 1] += k * gy
        wall_force[j, 2] += k * gz


@kernel(inline="always")
def _face_gradients(face, f, nvert, pos, wall, ref):
    """Six times face f's share of grad V at its corners a, b, c: b x c, c x a, a x b (corners
    relative to ref; m^2).
    # Model: face (nf, 3) int64, ref (3,) m   # Data in: pos (nvert, 3) m, wall (nwall, 3) m   # Data out: returns 9 floats
    """
    ax, ay, az = cavity_corner(face[f, 0], nvert, pos, wall, ref)
    bx, by, bz = cavity_corner(face[f, 1], nvert, pos, wall, ref)
    cx, cy, cz = cavity_corner(face[f, 2], nvert, pos, wall, ref)
    return (
        (by * cz - bz * cy, bz * cx - bx * cz, bx * cy - by * cx),
        (cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax),
        (ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx),
    )


@kernel
def add_cavity_pressure(face, ref, load_pa, pos, wall, vert_force, wall_force, to_points=True):
    """F_i += load grad_i V on the cavity's points: a pressure load_pa (Pa) inside the
    cavity, positive pushing its surface outward; the wall's forces are set, not added to;
    the membrane's points' only if to_points (implicit Euler adds theirs in its solve).
    # Model: face (nf, 3) int64, ref (3,) m   # Data in: load_pa Pa, pos (nvert, 3) m, wall (nwall, 3) m
    # Data out: vert_force (nvert, 3) N (added to), wall_force (nwall, 3) N
    """
    nvert = pos.shape[0]
    wall_force[:] = 0.0
    k = load_pa / 6.0
    for f in range(face.shape[0]):
        ga, gb, gc = _face_gradients(face, f, nvert, pos, wall, ref)
        _push(face[f, 0], nvert, k, ga[0], ga[1], ga[2], vert_force, wall_force, to_points)
        _push(face[f, 1], nvert, k, gb[0], gb[1], gb[2], vert_force, wall_force, to_points)
        _push(face[f, 2], nvert, k, gc[0], gc[1], gc[2], vert_force, wall_force, to_points)


@kernel
def cavity_volume_rate_gradient(face, point, ref, pos, vel, wall, wall_vel, grad):
    """`cavity_volume_rate`'s (V, dV/dt) and, in the same pass over the faces, grad V at each of
    the cavity's points (m^2): the step's pleural load is that pressure times it
    (`add_cavity_load`), and the bodies' share of the cavity's rate reads it at their points
    (`hybrid.wall_coupling.wall_rate_gradient`), so one pass gives all three (two passes before).
    # Model: face (nf, 3) int64 (a point i >= nvert is wall point i - nvert), point (np,) int64:
    #        the cavity's points (cavity indices), ref (3,) m
    # Data in: pos (nvert, 3) m, vel (nvert, 3) m/s, wall (nwall, 3) m, wall_vel (nwall, 3) m/s
    # Data out: returns (V, dV/dt); grad (nvert + nwall, 3) m^2, by cavity index (rows `point` set)
    """
    for k in range(point.shape[0]):
        i = point[k]
        grad[i, 0] = grad[i, 1] = grad[i, 2] = 0.0
    vol, rate = _volume_rate_pass(face, ref, pos, vel, wall, wall_vel, grad)
    for k in range(point.shape[0]):
        i = point[k]
        for d in range(3):
            grad[i, d] /= 6.0
    return vol, rate


@kernel
def add_cavity_load(point, load_pa, grad, vert_force, wall_force, to_points):
    """F_i += load grad_i V at the cavity's points (grad: `cavity_volume_rate_gradient`'s), as
    `add_cavity_pressure`: the wall's forces set, the membrane's added to if to_points.
    # Model: point (np,) int64, the cavity's points   # Data in: load_pa Pa, grad (nvert + nwall, 3) m^2
    # Data out: vert_force (nvert, 3) N (added to), wall_force (nwall, 3) N (set)
    """
    nvert = vert_force.shape[0]
    wall_force[:] = 0.0
    for k in range(point.shape[0]):
        i = point[k]
        if i >= nvert:
            for d in range(3):
                wall_force[i - nvert, d] = load_pa * grad[i, d]
        elif to_points:
            for d in range(3):
                vert_force[i, d] += load_pa * grad[i, d]


@kernel
def add_hold_pressure(face, ref, hold_pa, pos, wall, vert_free, vert_force, wall_force):
    """The occlusion's constraint pressure hold_pa (Pa, its last projection's) on the cavity's
    points that the projection does not move: the wall and the membrane's fixed and linked
    points (so that their bodies feel it), added to their forces.
    # Model: face (nf, 3) int64, ref (3,) m, vert_free (nvert,) uint8   # Data in: hold_pa, pos, wall
    # Data out: vert_force (nvert, 3) N, wall_force (nwall, 3) N (added to)
    """
    nvert = pos.shape[0]
    k = hold_pa / 6.0
    for f in range(face.shape[0]):
        for r in range(3):
            i = face[f, r]
            if i < nvert and vert_free[i]:
                continue
            ax, ay, az = cavity_corner(face[f, (r + 1) % 3], nvert, pos, wall, ref)
            bx, by, bz = cavity_corner(face[f, (r + 2) % 3], nvert, pos, wall, ref)
            _push(i, nvert, k, ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx, vert_force, wall_force, True)
