"""Passive fibres in a sheet: a tissue stiffer along one direction (continuum).

Connective tissue and the abdominal wall's transverse muscle carry load mostly
along their fibres. A sheet reinforced by fibres of direction f (unit, in its
plane) stores, per unit rest area, W = 1/2 E_f max(e_f, 0)^2, with E_f the
fibres' stiffness (N/m: fibre stress per unit fibre strain, times thickness)
and e_f = f . E f the Green strain along them; fibres are slack in compression.

On a linear triangle, f (x) f = sum_k c_k u_k (x) u_k over its rest edge
directions u_k (as for `muscle_fibres`), so the fibre strain is exactly
e_f = sum_k c_k e_k, e_k = (|x_j - x_i|^2 - L_k^2) / (2 L_k^2) the Green strain of
edge k. The energy of the triangle, A E_f / 2 max(e_f, 0)^2, depends on the edge
lengths only: its force, minus the gradient, has no net force nor moment, and
along edge k it is A E_f e_f g_k (x_j - x_i) on i and the opposite on j
(g_k = c_k / L_k^2).
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..errors import SceneError
from ..kernel import kernel
from .base import Rows, Term, force, param
from .fibres import fibre_coefficients

__all__ = ["PassiveFibres", "add_passive_fibres", "passive_fibres_energy"]

# pf_par columns: g_k = c_k / L_k^2 (1/m^2), L_k^2 (m^2) for the edges k = 0, 1, 2
# (corner k to k + 1), and A0 E_f (N m)
NPAR = 7


@force("passive_fibres")
class PassiveFibres(Term):
    """Passive fibres in the triangles of `region` (`Build.face_region`): a stiffness
    `modulus_n_per_m` (N/m: fibre stress per unit fibre strain, times thickness)
    along them, none across, slack in compression; added to the sheet's own
    elasticity (`membrane`). The fibres run around `around_axis` (circles about
    the line through `axis_point_m` (m) along it: hoops), toward the point
    `toward_m` (m), or along `axis`, projected on the surface."""

    formulations = ("continuum",)
    arrays = {"pf_vert": Rows(np.int32, 3), "pf_par": Rows(float, NPAR)}
    triangle_rows = "pf_vert"
    modulus_n_per_m: float = param("positive", hi=checks.MAX_STIFFNESS_N_PER_M)
    region: object = param("selector", "all")
    around_axis: tuple = param("vec3", None)
    axis_point_m: tuple = param("vec3", (0.0, 0.0, 0.0))
    toward_m: tuple = param("vec3", None)
    axis: tuple = param("vec3", None)

    def compile(self, b, what):
        idx = super().compile(b, what)
        given = [k for k in ("around_axis", "toward_m", "axis") if getattr(self, k) is not None]
        if len(given) != 1:
            raise SceneError(
                f"{what}: expected exactly one fibre direction, around_axis, toward_m or axis, "
                f"received {given or 'none'}"
            )
        mesh = b.mesh
        faces = b.face_region(self.region, what, idx)
        tri = mesh.face_vert[faces]
        direction = self._directions(mesh.vert_pos[tri].mean(axis=1), what)
        ok, c = fibre_coefficients(mesh.vert_pos, tri, direction)
        if not ok.any():
            raise SceneError(
                f"{what}.region: expected triangles in the region with fibres not normal to them, "
                f"found none among its {faces.size} triangles"
            )
        tri = tri[ok]
        p = mesh.vert_pos[tri]
        e = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)
        l2 = np.sum(e * e, axis=2)
        area = 0.5 * np.linalg.norm(np.cross(e[:, 0], -e[:, 2]), axis=1)
        mod = self.value("modulus_n_per_m", what)
        par = np.concatenate([c / l2, l2, (area * mod)[:, None]], axis=1)
        # stable-step estimate: the fibre's stiffness at each corner, A E_f (sum_k |g_k| L_k)^2
        k = area * mod * np.sum(np.abs(c) / np.sqrt(l2), axis=1) ** 2
        for corner in range(3):
            np.add.at(b.vert_stiffness, tri[:, corner], k)
        b.add_rows(pf_vert=tri, pf_par=par)

    def _directions(self, centroid, what) -> np.ndarray:
        if self.around_axis is not None:
            a = np.asarray(self.value("around_axis", what), float)
            if not np.linalg.norm(a) > 0:
                raise SceneError(f"{what}.around_axis: expected a non-zero vector, received {self.around_axis!r}")
            return np.cross(a / np.linalg.norm(a), centroid - np.asarray(self.value("axis_point_m", what)))
        if self.toward_m is not None:
            return np.asarray(self.value("toward_m", what), float) - centroid
        a = np.asarray(self.value("axis", what), float)
        if not np.linalg.norm(a) > 0:
            raise SceneError(f"{what}.axis: expected a non-zero vector, received {self.axis!r}")
        return np.tile(a, (len(centroid), 1))


@kernel
def add_passive_fibres(pf_vert, pf_par, vert_pos, vert_force):
    """Each triangle's fibre force, where its fibres are stretched (module docstring).
    # Model: pf_vert (n, 3) int32, pf_par (n, 7)   # Data in: vert_pos   # Data out: vert_force
    """
    for f in range(pf_vert.shape[0]):
        strain = 0.0
        for k in range(3):
            i = pf_vert[f, k]
            j = pf_vert[f, (k + 1) % 3]
            dx = vert_pos[j, 0] - vert_pos[i, 0]
            dy = vert_pos[j, 1] - vert_pos[i, 1]
            dz = vert_pos[j, 2] - vert_pos[i, 2]
            strain += 0.5 * pf_par[f, k] * (dx * dx + dy * dy + dz * dz - pf_par[f, 3 + k])
        if strain <= 0.0:
            continue  # slack
        for k in range(3):
            i = pf_vert[f, k]
            j = pf_vert[f, (k + 1) % 3]
            c = pf_par[f, 6] * strain * pf_par[f, k]
            for x in range(3):
                d = c * (vert_pos[j, x] - vert_pos[i, x])
                vert_force[i, x] += d
                vert_force[j, x] -= d


def passive_fibres_energy(pf_vert, pf_par, vert_pos) -> float:
    """sum over triangles of A0 E_f / 2 max(e_f, 0)^2 (J)."""
    p = vert_pos[pf_vert]
    e = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]], axis=1)
    strain = 0.5 * np.sum(pf_par[:, :3] * (np.sum(e * e, axis=2) - pf_par[:, 3:6]), axis=1)
    return float(np.sum(0.5 * pf_par[:, 6] * np.maximum(strain, 0.0) ** 2))
