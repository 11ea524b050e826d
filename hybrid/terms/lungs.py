"""The fourth structure: the lungs in the thoracic cavity, and the airway (paper 1 and 2).

**The cavity.** A closed surface made of the membrane's `floor` region (the dome's
thoracic face: its faces reversed) and a wall over the floor's border: the border
points raised along the floor's mean normal to a top plane `wall_height_m` above the
border's centre, in `hybrid.mesh.cavity.WALL_RINGS` rings (the same wall at every mesh level), closed by a fan to the top's
centre. The wall shares the border points with the membrane, so the cavity stays
closed however the membrane and the ribs that hold the border move; its other points
are fixed in the world (a rigid rib cage above the border: the ribs that carry the
border are the cavity's moving wall). Its volume is exact (the divergence theorem
over the closed surface, as the abdomen's); a floor whose faces do not have one
border loop, or a cavity with open edges, is refused when the scene compiles.

**The lungs fill the cavity** (the pleural space is a film of liquid): the lung
volume V is the cavity's, and its change is the air that flowed in through the airway.
A lumped law (a single compartment: the equation of motion of the respiratory system,
P = E V + R dV/dt, with Rohrer's flow-dependent resistance):

    P_alv = P_ao - (K1 + K2 |Q|) Q          (airway: Rohrer's resistance; Q = dV/dt, into the lungs)
    P_pl  = P_alv - P_L0 - E (V - V_rest)   (the lungs' elastic recoil, linear)

with P_ao the airway-opening pressure (a schedule: 0 for spontaneous breathing,
positive for a ventilator), P_L0 the recoil at the resting volume (P_pl = -P_L0 at
rest), E the lungs' elastance. Pleural pressure acts on the cavity's whole surface:
the dome's points and the border's points (which carry it to their ribs) take
(P_pl + P_L0) grad_i V, the virtual work of the pleural pressure's departure from rest.
The resting recoil itself is balanced in the rest shape (the chest wall's and the
diaphragm's resting stress, which the rest geometry holds): at rest nothing moves.
Zero elastance, resistance and opening pressure add exactly nothing.

Q in the law: with symplectic and explicit Euler the rate g . v at the step's start
(g = dV/dx); with implicit Euler the volume's change over the step in its solve
(`hybrid.implicit_lungs`), and at the step's start (the load on the wall and on the linked
points, which the ribs take) the last step's, the flow the solve ended with. The flow a run reports is each step's volume change over
h, whose sum is the volume change exactly.
Units: the scene's keys in the respiratory physiologist's units (cmH2O, L, s; names
say which); SI inside (Pa, m^3, s).
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

from ..errors import SceneError
from ..integrators import IMPLICIT_EULER_ID
from ..kernel import kernel
from ..mesh.cavity import open_edges, thoracic_cavity
from .base import Term, force, param
from .lung_cavity import (
    add_cavity_load,
    add_hold_pressure,
    cavity_corner,
    cavity_volume_rate_gradient,
)

__all__ = [
    "Lungs",
    "ADULT_LUNGS",
    "CMH2O_PA",
    "LungSlot",
    "NLUNG",
    "lung_load",
    "lung_recoil",
    "recoil_energy_j",
    "RECOIL_CURVES",
    "WALL_TOPS",
    "project_occluded",
    "thoracic_cavity",
    "open_edges",
]

#: one centimetre of water (Pa)
CMH2O_PA = 98.0665
#: cmH2O/L -> Pa/m^3 (an elastance, or a resistance per second)
CMH2O_PER_L = CMH2O_PA / 1e-3


class LungSlot(IntEnum):
    """The slots of `MembraneState.lung`: the compartment at the start of the last step."""

    VOLUME = 0  # m^3, the cavity's volume
    RATE = 1  # m^3/s, g . v: the volume's rate, into the lungs
    PLEURAL = 2  # Pa, pleural pressure
    ALVEOLAR = 3  # Pa, alveolar pressure
    AIRWAY = 4  # Pa, airway-opening pressure
    OCCLUDED = 5  # 1 while the airway is occluded, else 0
    HELD_VOLUME = 6  # m^3, the cavity's volume when the airway closed (held exactly while occluded)
    HOLD_PRESSURE = 7  # Pa, the occlusion's constraint pressure in the last step (0 when open)
    # m^4/kg, the last occluded projection's mobility of the cavity's volume, the abdomen's held:
    # sum_i |grad_i V|^2 / m_i over the free points, less the share the abdomen's constraint takes
    # (a Schur complement of its Gram matrix); the bodies' implicit hold (`hybrid.wall_coupling`)
    HOLD_MOBILITY = 8


NLUNG = len(LungSlot)
L_VOLUME, L_RATE, L_PLEURAL, L_ALVEOLAR, L_AIRWAY, L_OCCLUDED, L_HELD, L_HOLD, L_MOBILITY = LungSlot

# lung_par: elastance Pa/m^3, K1 Pa s/m^3, K2 Pa s^2/m^6, resting recoil Pa, the cavity's resting
# volume m^3; the recoil curve: 0 linear, 1 sigmoid, whose a, b (m^3), c, d (Pa) and the lungs'
# resting volume on it (m^3); the volume sums' origin (3, m: the cavity's rest centroid)
P_E, P_K1, P_K2, P_RECOIL, P_V0 = 0, 1, 2, 3, 4
P_CURVE, P_SA, P_SB, P_SC, P_SD, P_VREST = 5, 6, 7, 8, 9, 10
P_REF = 11
NPAR = 14
#: an adult's lungs and airway, each from a source, none fitted: lung compliance 0.2 L/cmH2O
#: (Guyton, Textbook of Medical Physiology), resting recoil 5 cmH2O (pleural pressure -5 cmH2O
#: at rest, physiology textbooks), airway resistance 1.5 cmH2O s/L (DuBois et al. 1956, J Clin
#: Invest 35:327); the packaged scenes with lungs take them as `Lungs(**ADULT_LUNGS, ...)`
ADULT_LUNGS = {
    "lung_compliance_l_per_cmh2o": 0.2,
    "resting_recoil_cmh2o": 5.0,
    "airway_resistance_cmh2o_s_per_l": 1.5,
}
#: the lungs' recoil curves (`Lungs.recoil_curve`)
RECOIL_CURVES = ("linear", "sigmoid")
#: what carries the cavity wall's top ring (`Lungs.wall_top`)
WALL_TOPS = ("fixed", "carried")


@kernel
def _two_volumes(face_vert, lung_face, ref, pos, wall, g1, g2, abdomen):
    """The abdomen's volume (faces face_vert; 0 unless abdomen) and the cavity's (lung_face)
    at pos (m^3), their gradients on the membrane's points into g1, g2 (m^2).
    # Model: face_vert (nface, 3), lung_face (nf, 3), ref (3,) m   # Data in: pos (nvert, 3) m, wall (nwall, 3) m
    # Data out: g1, g2 (nvert, 3) m^2; returns (m^3, m^3)
    """
    nvert = pos.shape[0]
    for i in range(nvert):
        for a in range(3):
            g1[i, a] = g2[i, a] = 0.0
    v1 = v2 = 0.0
    if abdomen:
        for f in range(face_vert.shape[0]):
            for r in range(3):
                i, j, k = face_vert[f, r], face_vert[f, (r + 1) % 3], face_vert[f, (r + 2) % 3]
                ax, ay, az = pos[j, 0] - ref[0], pos[j, 1] - ref[1], pos[j, 2] - ref[2]
                bx, by, bz = pos[k, 0] - ref[0], pos[k, 1] - ref[1], pos[k, 2] - ref[2]
                cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
                g1[i, 0] += cx / 6.0
                g1[i, 1] += cy / 6.0
                g1[i, 2] += cz / 6.0
                if r == 0:
                    v1 += (pos[i, 0] - ref[0]) * cx + (pos[i, 1] - ref[1]) * cy + (pos[i, 2] - ref[2]) * cz
    for f in range(lung_face.shape[0]):
        for r in range(3):
            i = lung_face[f, r]
            ax, ay, az = cavity_corner(lung_face[f, (r + 1) % 3], nvert, pos, wall, ref)
            bx, by, bz = cavity_corner(lung_face[f, (r + 2) % 3], nvert, pos, wall, ref)
            cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
            if i < nvert:
                g2[i, 0] += cx / 6.0
                g2[i, 1] += cy / 6.0
                g2[i, 2] += cz / 6.0
            if r == 0:
                px, py, pz = cavity_corner(i, nvert, pos, wall, ref)
                v2 += px * cx + py * cy + pz * cz
    return v1 / 6.0, v2 / 6.0


@kernel
def project_occluded(m, s, w, h, abdomen):
    """The occluded airway: the cavity's volume held at s.lung[HELD_VOLUME] exactly, with the
    abdomen's at m.vol0 when `abdomen` (both constraints share the dome's points). After free
    integration to X*, X = X* + phi1 d1 + phi2 d2, d_k = w_i grad_i V_k(X*) (w = 1/m on the
    free points), the two volumes solved for by Newton's method with exact gradients to their
    rounding; v += (phi1 d1 + phi2 d2) / h. Returns (phi1, phi2, ok): phi / h^2 the abdomen's
    pressure and the occlusion's pleural pressure (Pa).
    # Model: m.face_vert, m.lung_face, m.lung_par, m.vol0, m.vert_weight   # Data in: s.lung[HELD_VOLUME], wall
    # Data in/out: s.vert_pos, s.vert_vel   # Data out: s.grad (the abdomen's gradient at X*),
    #           s.lung[HOLD_MOBILITY]   # Scratch: w.lung_scratch (5, nvert, 3)
    """
    sc = w.lung_scratch
    x0, d1, d2, g1, g2 = sc[0], sc[1], sc[2], sc[3], sc[4]
    pos, vel, weight = s.vert_pos, s.vert_vel, m.vert_weight
    ref = m.lung_par[P_REF:]
    wall = s.lung_wall_pos
    n = pos.shape[0]
    v1, v2 = _two_volumes(m.face_vert, m.lung_face, ref, pos, wall, g1, g2, abdomen)
    for i in range(n):
        for a in range(3):
            x0[i, a] = pos[i, a]
            d1[i, a] = weight[i] * g1[i, a]
            d2[i, a] = weight[i] * g2[i, a]
            s.grad[i, a] = g1[i, a]
    t1, t2 = m.vol0, s.lung[L_HELD]
    tol1, tol2 = 16 * 2.0**-52 * abs(t1), 16 * 2.0**-52 * abs(t2)
    p1 = p2 = 0.0
    j11 = j12 = j21 = j22 = 0.0
    ok = False
    for _ in range(40):
        f1 = v1 - t1 if abdomen else 0.0
        f2 = v2 - t2
        if abs(f1) <= tol1 and abs(f2) <= tol2:
            ok = True
            break
        j11 = j12 = j21 = j22 = 0.0
        for i in range(n):
            for a in range(3):
                j11 += g1[i, a] * d1[i, a]
                j12 += g1[i, a] * d2[i, a]
                j21 += g2[i, a] * d1[i, a]
                j22 += g2[i, a] * d2[i, a]
        if abdomen:
            det = j11 * j22 - j12 * j21
            if not abs(det) > 0.0:
                break
            p1 -= (f1 * j22 - f2 * j12) / det
            p2 -= (j11 * f2 - j21 * f1) / det
        else:
            if not abs(j22) > 0.0:
                break
            p2 -= f2 / j22
        for i in range(n):
            for a in range(3):
                pos[i, a] = x0[i, a] + p1 * d1[i, a] + p2 * d2[i, a]
        v1, v2 = _two_volumes(m.face_vert, m.lung_face, ref, pos, wall, g1, g2, abdomen)
    if not ok:
        return p1, p2, False
    if j22 > 0.0:  # the last iteration's Gram matrix (none when the volumes held already)
        s.lung[L_MOBILITY] = j22 - j12 * j21 / j11 if abdomen and j11 > 0.0 else j22
    for i in range(n):
        for a in range(3):
            vel[i, a] += (p1 * d1[i, a] + p2 * d2[i, a]) / h
    return p1, p2, True


@kernel(inline="always")
def lung_recoil(par, vol):
    """The lungs' elastic recoil at the cavity's volume vol (m^3): (P_L(V) - P_L0 (Pa), dP_L/dV
    (Pa/m^3), the elastic energy above rest, the integral of P_L - P_L0 from rest (J)).
    Linear: E (V - V_rest). Sigmoid (Venegas, Harris & Simon 1998, J Appl Physiol 84:389, whose
    V = a + b / (1 + exp(-(P - c) / d)) inverted): P_L = c - d ln((a + b - V) / (V - a)), V the
    lungs' volume, their resting volume (where P_L = P_L0) plus the cavity's change; outside
    (a, a + b) it is not finite, which the step's check stops.
    # Model: par (`lung_par`)   # Data in: vol m^3   # Data out: returns (Pa, Pa/m^3, J)
    """
    dv = vol - par[P_V0]
    if par[P_CURVE] == 0.0:
        e = par[P_E]
        return e * dv, e, 0.5 * e * dv * dv
    a, b, c, d = par[P_SA], par[P_SB], par[P_SC], par[P_SD]
    v0 = par[P_VREST]
    v = v0 + dv
    x, u = v - a, a + b - v
    x0, u0 = v0 - a, a + b - v0
    p = c - d * math.log(u / x)
    energy = c * dv + d * (u * math.log(u) + x * math.log(x) - u0 * math.log(u0) - x0 * math.log(x0))
    return p - par[P_RECOIL], d * b / (x * u), energy - par[P_RECOIL] * dv


def recoil_energy_j(par, dv_m3):
    """`lung_recoil`'s elastic energy (J) at cavity volume changes dv_m3 (an array, m^3)."""
    dv = np.asarray(dv_m3, float)
    if par[P_CURVE] == 0.0:
        return 0.5 * par[P_E] * dv * dv
    a, b, c, d, v0 = par[P_SA], par[P_SB], par[P_SC], par[P_SD], par[P_VREST]
    x, u = v0 + dv - a, a + b - v0 - dv
    x0, u0 = v0 - a, a + b - v0
    energy = c * dv + d * (u * np.log(u) + x * np.log(x) - u0 * np.log(u0) - x0 * np.log(x0))
    return energy - par[P_RECOIL] * dv


@kernel(inline="always")
def lung_load(par, pao, vol, rate):
    """The lumped law (module docstring): (P_alv, P_pl + P_L0), the alveolar pressure and the
    pleural pressure's departure from rest (Pa), at the cavity's volume vol (m^3) and rate
    (m^3/s), the airway opening at pao (Pa).
    # Model: par (`lung_par`)   # Data in: pao Pa, vol m^3, rate m^3/s   # Data out: returns (Pa, Pa)
    """
    palv = pao - (par[P_K1] + par[P_K2] * abs(rate)) * rate
    return palv, palv - lung_recoil(par, vol)[0]


@kernel
def lungs_step_force(m, s, w, c):
    """The step's call (`Term.step_force`): the lumped law at the step's start (module
    docstring), its readouts into s.lung, the pleural load on the cavity's points.
    # Model: m.lung_face, m.lung_point, m.lung_par, m.lung_sched, m.vert_free
    # Data in: s.vert_pos, s.vert_vel, s.lung_wall_pos, s.lung_wall_vel, c.value, s.lung[HOLD_PRESSURE]
    # Data out: w.vert_force (added to), w.lung_wall_force (the wall's, to its bodies), s.lung (`LungSlot`),
    #           w.lung_grad (grad V at the cavity's points: the rigid phase reads the bodies' share)
    """
    par = m.lung_par
    ref = par[P_REF:]
    wall = s.lung_wall_pos
    grad = w.lung_grad
    vol, rate = cavity_volume_rate_gradient(
        m.lung_face, m.lung_point, ref, s.vert_pos, s.vert_vel, wall, s.lung_wall_vel, grad
    )
    pao = c.value[m.lung_sched[0], 0] * CMH2O_PA
    occluded = c.value[m.lung_sched[1], 0] >= 0.5
    if occluded and s.lung[L_OCCLUDED] == 0.0:  # the airway closes: its volume is held from here
        s.lung[L_HELD] = vol
    s.lung[L_OCCLUDED] = 1.0 if occluded else 0.0
    if occluded:  # no air through a closed airway (g . v is the projection's O(h) residue, not a flow)
        rate = 0.0
    elif m.integrator == IMPLICIT_EULER_ID:  # the flow implicit Euler's last solve ended with (module docstring)
        rate = (vol - s.lung[L_VOLUME]) / m.dt
    palv, load = lung_load(par, pao, vol, rate)  # load: the pleural pressure's departure from rest
    s.lung[L_VOLUME] = vol
    s.lung[L_RATE] = rate
    s.lung[L_PLEURAL] = load - par[P_RECOIL]
    s.lung[L_ALVEOLAR] = palv
    s.lung[L_AIRWAY] = pao
    # implicit Euler adds the membrane points' share in its solve (`hybrid.implicit.implicit_forces`)
    add_cavity_load(m.lung_point, load, grad, w.vert_force, w.lung_wall_force, m.integrator != IMPLICIT_EULER_ID)
    hold = s.lung[L_HOLD] if occluded else 0.0  # the occlusion's last pressure, to the bodies (as the abdomen's)
    if hold != 0.0:
        add_hold_pressure(m.lung_face, ref, hold, s.vert_pos, wall, m.vert_free, w.vert_force, w.lung_wall_force)
    s.lung[L_HOLD] = hold
    s.lung[L_PLEURAL] += hold
    s.lung[L_ALVEOLAR] += hold


@force("lungs")
class Lungs(Term):
    """The lungs and airway in the thoracic cavity over the membrane's dome (module
    docstring): P_pl = P_ao - (K1 + K2 |Q|) Q - P_L0 - E (V - V_rest), acting on the dome's
    thoracic face and the border points (and through them on their ribs).

    floor: the dome, the cavity's floor (faces of the region); wall_height_m: the top
    of the cavity over the floor's border (m); lung_elastance_cmh2o_per_l (or
    lung_compliance_l_per_cmh2o, its inverse: give one); resting_recoil_cmh2o: the lungs'
    recoil at rest, minus the resting pleural pressure; airway_resistance_cmh2o_s_per_l
    (Rohrer's K1) and rohrer_k2_cmh2o_s2_per_l2; airway_opening_pressure_cmh2o: a
    schedule (0: spontaneous breathing); recoil_curve: "linear" (by the elastance or compliance)
    or "sigmoid" (`lung_recoil`: sigmoid_lower_volume_l a, sigmoid_volume_range_l b,
    sigmoid_inflection_cmh2o c, sigmoid_width_cmh2o d of V = a + b / (1 + exp(-(P - c) / d)),
    P the transpulmonary pressure); wall_bodies: a body name or pattern of the rigid model (the
    upper ribs, `rigid.ribs`), None for none: the wall's rings between the border and the top
    follow the nearest such body by the share the border's rib leaves, each ring point the
    displacement of the body's point beside it (the pulmonary rib cage); wall_top: "fixed" (the
    top ring stays where it is: a rigid upper rib cage above the wall) or "carried" (the top ring
    follows the nearest of `wall_bodies` wholly, so that the pair's pump-handle turn moves the
    cavity's wall outward, about 1 L/rad a rib on `breathing_lungs` against 0.15 fixed; needs
    `wall_bodies`);
    airway_occluded: a schedule, the airway closed where
    it is 1 (>= 0.5), open where 0: the lung volume when it closes is then held exactly
    (`project_occluded`), as in the occlusion and twitch manoeuvres, the hold shared with the bodies
    that carry the cavity (`hybrid.wall_coupling.hold_with_bodies`)."""

    # lung_face (nf, 3) int64: the cavity (points >= nvert on the wall); lung_wall (nwall, 3) m;
    # lung_par (NPAR,): see P_*; lung_sched (2,) int64: the schedule rows of the airway-opening
    # pressure and of the occlusion; lung_point (np,) int64: the cavity's points (its indices)
    arrays = {
        "lung_face": lambda n: np.zeros((0, 3), np.int64),
        "lung_wall": lambda n: np.zeros((0, 3)),
        "lung_par": lambda n: np.zeros(NPAR),
        "lung_sched": lambda n: np.zeros(2, np.int64),
        "lung_point": lambda n: np.zeros(0, np.int64),
    }
    # the step's call; implicit Euler's solve takes the load on the dome's points itself
    # (`hybrid.implicit_lungs`), and an occluded airway's projection is the step's (`project_occluded`)
    step_force = lungs_step_force
    wall_height_m: float = param("positive", hi=10.0)
    floor: object = param("selector", "diaphragm")
    lung_elastance_cmh2o_per_l: float = param("nonneg", None, hi=1e4)
    lung_compliance_l_per_cmh2o: float = param("positive", None, hi=1e4)
    resting_recoil_cmh2o: float = param("nonneg", 5.0, hi=100.0)
    airway_resistance_cmh2o_s_per_l: float = param("nonneg", 0.0, hi=1e4)
    rohrer_k2_cmh2o_s2_per_l2: float = param("nonneg", 0.0, hi=1e4)
    airway_opening_pressure_cmh2o: object = param("schedule", 0.0, ncomp=1)
    airway_occluded: object = param("schedule", 0.0, ncomp=1)
    wall_bodies: str = param("text", None)
    wall_top: str = param("choice", "fixed", choices=WALL_TOPS)
    recoil_curve: str = param("choice", "linear", choices=RECOIL_CURVES)
    sigmoid_lower_volume_l: float = param("nonneg", None, hi=100.0)
    sigmoid_volume_range_l: float = param("positive", None, hi=100.0)
    sigmoid_inflection_cmh2o: float = param("nonneg", None, hi=100.0)
    sigmoid_width_cmh2o: float = param("positive", None, hi=1e3)

    def compile(self, b, what):
        super().compile(b, what)
        if "lung_face" in b.out:
            raise SceneError(f"{what}: expected one lungs term, received a second (the scene has one thorax)")
        ela, comp = self.lung_elastance_cmh2o_per_l, self.lung_compliance_l_per_cmh2o
        curve = self.value("recoil_curve", what)
        sig_names = (
            "sigmoid_lower_volume_l",
            "sigmoid_volume_range_l",
            "sigmoid_inflection_cmh2o",
            "sigmoid_width_cmh2o",
        )
        sig = [getattr(self, k) for k in sig_names]
        if curve == "linear" and (ela is None) == (comp is None):
            raise SceneError(
                f"{what}: expected exactly one of lung_elastance_cmh2o_per_l or lung_compliance_l_per_cmh2o, "
                f"received lung_elastance_cmh2o_per_l={ela!r} lung_compliance_l_per_cmh2o={comp!r}"
            )
        given = [k for k, v in zip(sig_names, sig) if v is not None]
        if curve == "linear" and given:
            raise SceneError(
                f"{what}.{given[0]}: a parameter of recoil_curve = 'sigmoid', received recoil_curve = 'linear'"
            )
        if curve == "sigmoid":
            missing = [k for k, v in zip(sig_names, sig) if v is None]
            if missing or ela is not None or comp is not None:
                raise SceneError(
                    f"{what}: recoil_curve = 'sigmoid' expects {', '.join(sig_names)} and no elastance or "
                    f"compliance, received {'no ' + missing[0] if missing else 'an elastance or compliance'}"
                )
        e = 0.0
        if curve == "linear":
            e = (
                self.value("lung_elastance_cmh2o_per_l", what)
                if ela is not None
                else 1.0 / self.value("lung_compliance_l_per_cmh2o", what)
            )
        b.mesh.require_closed(f"{what}: the lungs' floor is the dome of a closed membrane")
        sel_idx = b.region(self.floor, f"{what}.floor")
        floor = b.mesh.face_vert[b.face_region(self.floor, f"{what}.floor", sel_idx)]
        face, wall, _, under, weight = thoracic_cavity(b.mesh.vert_pos, floor, self.value("wall_height_m", what), what)
        pts = np.concatenate([b.mesh.vert_pos, wall])
        ref = pts[np.unique(face)].mean(axis=0)
        q = pts[face] - ref
        vol = float(np.einsum("ij,ij->i", q[:, 0], np.cross(q[:, 1], q[:, 2])).sum() / 6.0)
        if not vol > 0:
            raise SceneError(f"{what}: expected a thoracic cavity of positive volume, received {vol:.4g} m^3")
        par = np.zeros(NPAR)
        par[P_E] = e * CMH2O_PER_L
        par[P_K1] = self.value("airway_resistance_cmh2o_s_per_l", what) * CMH2O_PER_L
        par[P_K2] = self.value("rohrer_k2_cmh2o_s2_per_l2", what) * CMH2O_PA / 1e-6
        par[P_RECOIL] = self.value("resting_recoil_cmh2o", what) * CMH2O_PA
        par[P_V0] = vol
        if curve == "sigmoid":
            lower, span, inflection, width = (self.value(k, what) for k in sig_names)
            par[P_CURVE] = 1.0
            par[P_SA], par[P_SB] = lower * 1e-3, span * 1e-3
            par[P_SC], par[P_SD] = inflection * CMH2O_PA, width * CMH2O_PA
            # the lungs' resting volume: where the curve gives the resting recoil
            par[P_VREST] = par[P_SA] + par[P_SB] / (1.0 + math.exp(-(par[P_RECOIL] - par[P_SC]) / par[P_SD]))
        par[P_REF:] = ref
        row = b.schedule(self.airway_opening_pressure_cmh2o, f"{what}.airway_opening_pressure_cmh2o", 1)
        shut = b.schedule(self.airway_occluded, f"{what}.airway_occluded", 1)
        b.out.update(
            lung_face=face,
            lung_wall=wall,
            lung_par=par,
            lung_sched=np.array([row, shut], np.int64),
            lung_point=np.unique(face).astype(np.int64),
        )
        # the wall's points that rigid bodies carry (`hybrid.rigid.build_rigid`)
        bodies, top = self.value("wall_bodies", what), self.value("wall_top", what)
        if top == "carried" and bodies is None:
            raise SceneError(
                f"{what}.wall_top: 'carried' needs wall_bodies (the bodies that carry the top ring), received none"
            )
        b.carried = (wall, under, weight, bodies, top == "carried")
        # (no per-point stiffness for the stability estimate: the compartment moves the dome as one
        # mode, E sum_i |g_i|^2 / m_i, about 700 s^-2 on the breathing scene, far below the sheet's)

    @classmethod
    def finish(cls, b):  # the arrays are the one term's, set by compile
        pass
