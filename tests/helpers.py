"""Set-up shared by several test files that is not a fixture (tests/conftest.py holds
those): scenes, meshes, an observer and readers. Importable as `helpers` (pyproject's
pytest `pythonpath`)."""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import numpy as np

from hybrid.mesh import Mesh, icosphere, uv_sphere
from hybrid.regions import HalfSpace
from hybrid.scene import Damping, Gravity, Masses, MeshSpec, Nailed, Scene, ShapeMemory, Volume

EPS = np.finfo(float).eps

# MuJoCo's humanoid, an MJCF model written by others (vendored from gymnasium, MIT: humanoid.xml.LICENSE)
HUMANOID_XML = Path(__file__).parent / "data" / "humanoid.xml"


# ----------------------------------------------------------------- scenes

# the 80-point sphere under gravity, hanging from its nailed bottom cap, incompressible
BASE = Scene(
    formulation="paper",
    mesh=MeshSpec(),
    masses=Masses(total_kg=4.0),
    regions={
        "bottom": HalfSpace((0.0, 0.0, -0.1), (0.0, 0.0, -1.0)),
        "top": HalfSpace((0.0, 0.0, 0.05), (0.0, 0.0, 1.0)),
    },
    forces=(Gravity(), ShapeMemory(3000.0), Damping(critical_fraction=0.3)),
    constraints=(Nailed("bottom"), Volume()),
    dt_s=1e-3,
)


def dense_matrix(n, product):
    """The (3n, 3n) matrix of a product product(u, y) (y = A u on (n, 3) arrays), column by column."""
    out = np.zeros((3 * n, 3 * n))
    for j in range(3 * n):
        u, y = np.zeros((n, 3)), np.zeros((n, 3))
        u.flat[j] = 1.0
        product(u, y)
        out[:, j] = y.ravel()
    return out


def central_differences(fun, x, eps):
    """d fun / d x (x.size x x.size) by central differences of step eps."""
    out = np.zeros((x.size, x.size))
    for j in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp.flat[j] += eps
        xm.flat[j] -= eps
        out[:, j] = ((fun(xp) - fun(xm)) / (2.0 * eps)).ravel()
    return out


def forces_at(model, pos, t: float = 0.0):
    """The force pass of `model` with its points at `pos` (m), time t (s): (forces (nvert, 3) N,
    the state after the pass, for its readouts such as the pressure)."""
    from hybrid.implicit_work import no_implicit_work
    from hybrid.step import membrane_forces
    from hybrid.step_work import new_control, new_state, new_work

    state = new_state(model.arrays)
    state.vert_pos[:] = pos
    work = new_work(model.arrays, state)
    membrane_forces(model.arrays, state, work, no_implicit_work(model.arrays), new_control(model.arrays), t)
    return work.vert_force.copy(), state


def every_row(arrays):
    """The Newton rows of every triangle of a model's arrays (none left out for fixed corners), of
    the types implicit Euler's solve passes its kernels (`hybrid.implicit_work.newton_rows`): a test
    calling those kernels with them loads the solve's compiled build instead of compiling its own."""
    from hybrid.implicit_work import NewtonRows

    return NewtonRows(*(np.array(getattr(arrays, name)) for name in NewtonRows._fields))


def no_planes(arrays):
    """No sliding planes, of the type implicit Euler's solve passes (`hybrid.terms.slide_planes`)."""
    from hybrid.terms.slide_planes import slide_planes

    return slide_planes(arrays.vert_free)


def base_scene(**changes) -> Scene:
    return dataclasses.replace(BASE, **changes)


def with_force(term) -> Scene:
    return base_scene(forces=BASE.forces + (term,))


def with_constraint(term) -> Scene:
    return base_scene(constraints=BASE.constraints + (term,))


def hanging_sphere(dt, integrator, kv=50.0, m=0.05):
    """Heavily damped (kv^2 > 4 m k): the explicit bound 4m / (kv + sqrt(kv^2 - 4mk))
    is then close to the paper's 2m/kv (2.1e-3 s against 2e-3 s)."""
    return Scene(
        formulation="paper",
        mesh=MeshSpec(),
        masses=Masses(per_vertex_kg=(m,) * 80),
        regions={"bottom": HalfSpace((0.0, 0.0, -0.1), (0.0, 0.0, -1.0))},
        forces=(Gravity(), ShapeMemory(3000.0), Damping(coef_n_s_per_m=kv)),
        constraints=(Nailed("bottom"), Volume()),
        dt_s=dt,
        integrator=integrator,
    )


# ----------------------------------------------------------------- meshes


def open_hemisphere() -> Mesh:
    base = uv_sphere(0.12, 13, 8)
    face = base.face_vert[base.vert_pos[base.face_vert].mean(axis=1)[:, 2] > 0.0]
    used = np.unique(face)
    remap = np.full(base.nvert, -1)
    remap[used] = np.arange(used.size)
    return Mesh.from_arrays(base.vert_pos[used], remap[face], name="hemisphere")


def torus(major=1.0, minor=0.3, n_major=24, n_minor=12, center=(0.0, 0.0, 0.0)) -> Mesh:
    """A closed genus-1 surface (non-convex), outward faces."""
    u = 2 * np.pi * np.arange(n_major) / n_major
    v = 2 * np.pi * np.arange(n_minor) / n_minor
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = major + minor * np.cos(vv)
    pos = np.stack([ring * np.cos(uu), ring * np.sin(uu), minor * np.sin(vv)], axis=-1)
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    i1, j1 = (i + 1) % n_major, (j + 1) % n_minor
    idx = lambda a, b: (a * n_minor + b).ravel()  # noqa: E731
    # dP/du x dP/dv points outward, so (i, j) -> (i+1, j) -> (i+1, j+1) is counter-clockwise.
    face = np.concatenate(
        [
            np.stack([idx(i, j), idx(i1, j), idx(i1, j1)], axis=1),
            np.stack([idx(i, j), idx(i1, j1), idx(i, j1)], axis=1),
        ]
    )
    return Mesh.from_arrays(pos.reshape(-1, 3) + center, face, name="torus")


def dented_sphere(center=(0.0, 0.0, 0.0)) -> Mesh:
    """A star-shaped, non-convex closed surface: icosphere(3) with a wavy radius."""
    base = icosphere(3)
    x, y, z = base.vert_pos.T
    theta, phi = np.arccos(z), np.arctan2(y, x)
    radius = 1.0 + 0.35 * np.sin(3 * theta) * np.cos(2 * phi)
    return Mesh.from_arrays(base.vert_pos * radius[:, None] + center, base.face_vert, name="dented")


def submesh(mesh: Mesh, keep_face: np.ndarray, name="sub") -> Mesh:
    """The faces in keep_face (bool mask) with their vertices, re-indexed."""
    face = mesh.face_vert[keep_face]
    used = np.unique(face)
    new_index = np.full(mesh.nvert, -1)
    new_index[used] = np.arange(len(used))
    return Mesh.from_arrays(mesh.vert_pos[used], new_index[face], name=name)


def hemisphere() -> Mesh:
    """The upper half of a UV sphere with an equator circle: an open surface."""
    sphere = uv_sphere(rings=8)
    keep = np.all(sphere.vert_pos[sphere.face_vert][:, :, 2] > -1e-9, axis=1)
    return submesh(sphere, keep, name="hemisphere")


CLOSED = {
    "uv_sphere": lambda c: uv_sphere(center=c),
    "icosphere3": lambda c: icosphere(3, center=c),
    "dented": dented_sphere,
    "torus": lambda c: torus(center=c),
}


def sphere_arrays():
    """The 80-point sphere's arrays, writable, for corrupting."""
    m = uv_sphere()
    return np.array(m.vert_pos), np.array(m.face_vert)


# ----------------------------------------------------------------- the rigid part

RIBS = ("rib_left", "rib_right")


# ----------------------------------------------------------------- recordings and studies


class FrameCopies:
    """An observer keeping what the simulation holds at each frame."""

    def __init__(self):
        self.t, self.pos, self.xpos, self.xquat = [], [], [], []

    def __call__(self, sim, trace):
        self.t.append(sim.time)
        self.pos.append(np.array(sim.vert_pos))
        if sim.mj_data is not None:
            self.xpos.append(np.array(sim.mj_data.xpos[1:]))
            self.xquat.append(np.array(sim.mj_data.xquat[1:]))


def decoded_messages(path, topics):
    """(log time, message) of each message on `topics`, decoded by mcap's own protobuf
    decoder from the schemas the file holds."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(m.log_time, msg) for _, _, m, msg in reader.iter_decoded_messages(topics=topics)]


def strict_load(path):
    def no_constant(name):
        raise ValueError(f"non-finite constant {name} in {path}")

    return json.loads(path.read_text(), parse_constant=no_constant)


# the lungs' tests (tests/test_lungs.py, tests/test_respiratory_readouts.py): a rigid cage and a prescribed dome
DOME_Z_M = 0.045


def dome_scene(lungs, displacement_m, duration_s: float = 4.0, dt_s: float = 1e-3) -> Scene:
    """A sphere whose cap above z = 0.045 m (the dome, the lungs' cavity's floor) follows
    `displacement_m`, the rest nailed: a rigid rib cage and a prescribed dome."""
    from hybrid.regions import Difference
    from hybrid.scene import Prescribed

    return Scene(
        formulation="continuum",
        name="prescribed_dome",
        mesh=MeshSpec(generator="ring_sphere", radius_m=0.12, level=1, conform_z_m=(DOME_Z_M,)),
        masses=Masses(total_kg=4.0),
        regions={
            "diaphragm": HalfSpace((0.0, 0.0, DOME_Z_M), (0.0, 0.0, 1.0)),
            "below": Difference("all", "diaphragm"),
        },
        forces=(lungs,),
        constraints=(Nailed("below"), Prescribed("diaphragm", displacement_m)),
        dt_s=dt_s,
        integrator="symplectic_euler",
        duration_s=duration_s,
    )


# ----------------------------------------------------------------- one ellipsoid in two triangulations

#: the ellipsoid of tests/mesh/test_two_triangulations.py and its study (semi-axes, m: a trunk's size)
ELLIPSOID_AXES_M = (0.15, 0.12, 0.10)
#: the point counts of its two families of files, coarse to fine, the spacing halved a step (points x 4):
#: a regular triangulation (an icosphere's, subdivisions 1-3) and an irregular one (`irregular_sphere`:
#: the spiral points moved at random by up to a third of their spacing, their convex hull)
ELLIPSOID_FILES = {"regular": (42, 162, 642), "irregular": (40, 160, 640)}
#: the irregular family's random moves
ELLIPSOID_SEED = 28


def ellipsoid_volume_m3(axes_m=ELLIPSOID_AXES_M) -> float:
    a, b, c = axes_m
    return 4.0 / 3.0 * np.pi * a * b * c


def ellipsoid_area_m2(axes_m=ELLIPSOID_AXES_M) -> float:
    """Legendre's closed form, a >= b >= c: 2 pi c^2 + 2 pi a b (E(phi, m) sin^2 phi + F(phi, m)
    cos^2 phi) / sin phi, cos phi = c / a, m = a^2 (b^2 - c^2) / (b^2 (a^2 - c^2))."""
    from scipy.special import ellipeinc, ellipkinc

    a, b, c = sorted(axes_m, reverse=True)
    phi = np.arccos(c / a)
    m = a * a * (b * b - c * c) / (b * b * (a * a - c * c))
    s = np.sin(phi)
    return float(
        2 * np.pi * c * c + 2 * np.pi * a * b / s * (ellipeinc(phi, m) * s * s + ellipkinc(phi, m) * (1 - s * s))
    )


def ellipsoid_triangulation(family: str, npoint: int, axes_m=ELLIPSOID_AXES_M) -> tuple[np.ndarray, np.ndarray]:
    """(vert_pos, face_vert) of a family of `ELLIPSOID_FILES`: the unit sphere's points and faces
    stretched onto the ellipsoid (x a, y b, z c): each point on it; a convex hull stays one."""
    if family == "regular":
        sphere = icosphere({42: 1, 162: 2, 642: 3}[npoint])
    else:
        from hybrid.mesh import irregular_sphere

        sphere = irregular_sphere(npoint, seed=ELLIPSOID_SEED)
    return sphere.vert_pos * np.asarray(axes_m), np.array(sphere.face_vert)


def write_ellipsoid(folder: Path, family: str, npoint: int, axes_m=ELLIPSOID_AXES_M) -> Path:
    """The triangulation written as an OBJ file in `folder`; its path."""
    path = Path(folder) / f"ellipsoid_{family}_{npoint}.obj"
    Mesh.from_arrays(*ellipsoid_triangulation(family, npoint, axes_m), name=path.stem).save(path)
    return path


#: Roache's factor of safety on a discretisation error estimated from two meshes at an order
#: not observed but assumed (the grid convergence index), and on one from three meshes at the order
#: they observe (Roache 1998, Verification and Validation in Computational Science and Engineering)
SAFETY_TWO_MESHES = 3.0
SAFETY_THREE_MESHES = 1.25


def family_errors(values, level_errors, ratio: float = 2.0, order: float = 2.0) -> dict:
    """A family of files of one shape, coarse to fine, the spacing divided by `ratio` a file, and a
    value of each (the limit of its own levels, known to `level_errors`): each value's estimated
    distance from the shape's ("sampling": the finest's the grid convergence index of the two
    finest at the formal `order`, SAFETY_TWO_MESHES |x_n - x_n-1| / (ratio^order - 1); a coarser
    one's at most its distance to the next plus that one's, each distance widened by both
    values' level errors), and the family's limit (Richardson at `order`) with its error
    estimate (its distance from the finest value plus the finest's)."""
    from hybrid.studies.convergence import richardson

    x, e = list(values), list(level_errors)
    d = [abs(x[i + 1] - x[i]) + e[i] + e[i + 1] for i in range(len(x) - 1)]
    sampling = [SAFETY_TWO_MESHES * d[-1] / (ratio**order - 1.0) + e[-1]]
    for i in reversed(range(len(d))):
        sampling.insert(0, d[i] + sampling[0])
    limit = richardson(x, ratio, order=order)[0]
    return {"values": x, "sampling": sampling, "limit": limit, "limit_error": abs(limit - x[-1]) + sampling[-1]}


def limit_allowance(estimate: dict, ratio: float, order: float = 2.0) -> float:
    """How far a convergence study's limit (`hybrid.studies.convergence.estimate`, one metric)
    may be from the exact one: its own error estimate where it has one; where it has none (three
    levels whose order they fit), the grid convergence index of its two finest levels, Fs |x_K -
    x_K-1| / (ratio^p - 1), plus the limit's distance from the finest level (the index bounds that
    level's error): Fs = SAFETY_THREE_MESHES at the order the levels show, at most the method's
    formal `order`, or SAFETY_TWO_MESHES at the formal order where they show none."""
    if estimate["limit_error_estimate"] is not None:
        return float(estimate["limit_error_estimate"])
    x = estimate["value_by_level"]
    observed = estimate["observed_order_space"]
    safety, p = (SAFETY_TWO_MESHES, order) if observed is None else (SAFETY_THREE_MESHES, min(observed, order))
    return safety * abs(x[-1] - x[-2]) / (ratio**p - 1.0) + abs(estimate["limit"] - x[-1])


def cavity_volume(sim, rig, qpos_change) -> float:
    """The thoracic cavity's volume with the rigid bodies moved by qpos_change from where they are
    (the carried wall and the linked points with them; the free points where they are)."""
    import mujoco  # here: the suite's conftest imports this module, and a membrane-only test loads no MuJoCo

    from hybrid.wall_coupling import carry_wall

    m, d = sim.mj_model, copy.copy(sim.mj_data)
    mujoco.mj_integratePos(m, d.qpos, qpos_change, 1.0)
    mujoco.mj_forward(m, d)
    state = sim.get_state()
    wall = state.lung_wall_pos.copy()
    carry_wall(rig.wall, d.site_xpos, wall, np.zeros_like(wall))
    pos = state.vert_pos.copy()
    pos[rig.links.vert] = d.site_xpos[rig.links.site_id]
    every = np.vstack([pos, wall])
    face = sim.model.arrays.lung_face
    a, b, c = every[face[:, 0]], every[face[:, 1]], every[face[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
