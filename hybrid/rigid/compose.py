"""Spec composition: what hybrid adds to a loaded `mujoco.MjSpec` before compiling it
once — articulated ribs (`rigid.ribs`, `hybrid.rigid.ribs`), an attachment site per linked membrane point on its body, at the point's rest
position, and optionally the points' masses on their bodies (`build_rigid`, called by
`compile_scene` for scenes with a `Rigid` part) — and the free body of the rigid
validation study (`free_body_spec`).

Link masses: with `Rigid.add_link_mass` (the default) each linked point's mass m_i
is added to its body at the site (the paper's rigid region carries its points'
masses; light ribs under explicit force transfer are unstable otherwise). MuJoCo
then applies that mass's weight itself, which the coupled step corrects
(`hybrid.coupling`). Attachment sites of a scene are named
f"{Rigid.prefix}hybrid_link_{i}", i the vertex index.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Sequence

import mujoco
import numpy as np

from hybrid import regions as _regions
from hybrid.errors import RigidError, SceneError
from hybrid.mesh.geometry import cross_rows, scatter_corners, vertex_area
from hybrid.scene import KeepIn, Nailed, Prescribed, Rigid, RigidLink, Scene
from hybrid.terms.base import claim_points

from .controls import apply_controls, close_names, start_data
from .mjcf import compile_spec, load_rigid_spec
from .ribs import add_ribs
from .system import CoupledRigid

_SITE_STEM = "hybrid_link_"
_SITE_SIZE_M = [0.002, 0.002, 0.002]
_SITE_GROUP = 4  # hidden in the viewer by default, like the point-mass geoms (group 5)
_INERTIA_FROM_GEOM_TRUE = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
_POINT_GEOM_RADIUS = 1e-4  # m: the geoms that carry point masses (inertia 0.4 m r^2, negligible)


def _body_names(spec: mujoco.MjSpec) -> list[str]:
    return [b.name for b in spec.bodies]


def _taken_sites(spec: mujoco.MjSpec, site_names: Sequence[str]) -> list[str]:
    return [s for s in site_names if spec.site(s) is not None]


def add_sites(
    spec: mujoco.MjSpec,
    model0: mujoco.MjModel,
    body_names: Sequence[str],
    point_pos: np.ndarray,
    site_names: Sequence[str],
    key_id: int = -1,
) -> np.ndarray:
    """Add site `site_names[j]` to body `body_names[j]` at world position `point_pos[j]`
    (m) of the model's pose at `qpos0` (or at keyframe key_id); model0 is `spec` compiled
    (before the sites). Returns (n, 3) m, the sites' positions in their bodies' frames."""
    data0 = start_data(model0, key_id)
    local = np.empty((len(site_names), 3))
    for j, (name, p) in enumerate(zip(body_names, point_pos)):
        bid = model0.body(name).id
        rot = data0.xmat[bid].reshape(3, 3)
        local[j] = rot.T @ (p - data0.xpos[bid])
        spec.body(name).add_site(name=site_names[j], pos=local[j].tolist(), size=_SITE_SIZE_M, group=_SITE_GROUP)
    return local


def attach_points(
    spec: mujoco.MjSpec, body_names: Sequence[str], point_pos: np.ndarray, prefix: str = "hybrid_link_"
) -> list[str]:
    """Add one site per linked point to its body, at the point's world rest position.

    The spec is compiled once to get the bodies' world poses at `qpos0`; each point is
    converted into its body's frame, so that the site sits exactly at the point when
    the model is at `qpos0`. The spec is modified in place (sites added).

    Parameters
    ----------
    spec : the model to modify.
    body_names : (n,) the body each point is linked to ("world" fixes it in space).
    point_pos : (n, 3) m, the points' world rest positions.
    prefix : site i is named f"{prefix}{i}".

    Returns
    -------
    (n,) the site names, in point order.

    Raises
    ------
    RigidError : shapes differ, a position is not finite, a body name is unknown (the
        message lists the available bodies), or a site name is already taken.
    """
    pos = np.asarray(point_pos, dtype=float)
    names = list(body_names)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise RigidError(f"point_pos: expected shape (n, 3), got {pos.shape}")
    if len(names) != pos.shape[0]:
        raise RigidError(f"body_names: expected {pos.shape[0]} names (one per point), got {len(names)}")
    if not np.all(np.isfinite(pos)):
        bad = int(np.flatnonzero(~np.isfinite(pos).all(axis=1))[0])
        raise RigidError(f"point_pos[{bad}]: expected finite coordinates, got {pos[bad]}")
    unknown = sorted({n for n in names if spec.body(n) is None})
    if unknown:
        raise RigidError(f"unknown body name(s) {unknown}; available bodies: {_body_names(spec)}")
    site_names = [f"{prefix}{i}" for i in range(len(names))]
    taken = _taken_sites(spec, site_names)
    if taken:
        raise RigidError(
            f"site name(s) already in the model: {taken[:5]}"
            f"{' ...' if len(taken) > 5 else ''}; choose another prefix than "
            f"{prefix!r}"
        )
    add_sites(spec, compile_spec(spec), names, pos, site_names)
    return site_names


def build_rigid(
    scene: Scene, mesh, regions: dict, vert_mass: np.ndarray, carried: tuple | None = None
) -> tuple[CoupledRigid, np.ndarray]:
    """Load and compile the rigid part of `scene`; returns (CoupledRigid, link_vert).

    mesh: the membrane (`hybrid.mesh.Mesh`, rest positions in m); regions: evaluated
    regions {name: vertex indices}; vert_mass (nvert,) kg. link_vert (n,) int32 are the
    linked vertices, sorted, each with a site `f"{prefix}hybrid_link_{i}"` at its rest
    position on its body. Raises SceneError (malformed links, a point linked twice or
    also nailed/prescribed) or RigidError (missing or unparsable MJCF, unknown body,
    taken site name, a model MuJoCo cannot compile; a body, joint, actuator or keyframe
    the control keys name that the model lacks: `hybrid.rigid.controls`), each a
    one-line message. The sites are placed where the bodies start (`rigid.keyframe`).
    carried: (pos (n, 3) m, under (n,), weight (n,), body pattern or None, top carried), points
    off the membrane (the lungs' wall) each carried by `weight` of the motion of the body that
    holds membrane point `under`: those over a linked point get a site `f"{prefix}hybrid_wall_{j}"`
    on its body (`_carried_sites`).
    """
    rig = scene.rigid
    if not isinstance(rig, Rigid):
        raise SceneError(f"rigid: expected a hybrid.scene.Rigid, received {type(rig).__name__}")
    if not isinstance(rig.prefix, str):
        raise SceneError(f"rigid.prefix: expected a string, received {rig.prefix!r}")
    if not isinstance(rig.add_link_mass, bool):
        raise SceneError(f"rigid.add_link_mass: expected true or false, received {rig.add_link_mass!r}")
    spec, label, source = load_rigid_spec(scene)
    controls = apply_controls(spec, rig, label, scene.dt_s)
    # the ribs after the control keys (their patterns name the model's own joints), before
    # the links (which may name the rib bodies)
    ribs = add_ribs(spec, rig.ribs, label, controls.key_id) if rig.ribs is not None else None
    bodies = _body_names(spec)
    sites = [s.name for s in spec.sites if s.name]

    owner: dict[int, int] = {}  # vertex -> link index
    link_body_of: dict[int, str] = {}
    slide_of: dict[int, float] = {}  # sliding vertex -> its link's stiffness (N/m^3)
    for k, link in enumerate(rig.links):
        what = f"rigid.links[{k}]"
        if not isinstance(link, RigidLink):
            raise SceneError(f"{what}: expected a hybrid.scene.RigidLink, received {type(link).__name__}")
        body = _link_body(spec, link.body)
        if body is None:
            raise RigidError(
                f"{what}.body: no body or site named {link.body!r} in {label}; "
                f"available bodies: {bodies}; sites: {sites}"
            )
        idx = _regions.select_on(link.region, mesh, name=f"{what}.region", regions=regions)
        twice = [int(i) for i in idx if int(i) in owner]
        if twice:
            raise SceneError(
                f"{what}.region: vertices {twice[:8]} are already linked by "
                f"rigid.links[{owner[twice[0]]}]; expected each point linked to one body"
            )
        slide_k = link.slide_stiffness_n_per_m3
        if not (isinstance(slide_k, (int, float)) and np.isfinite(slide_k) and slide_k >= 0):
            raise SceneError(f"{what}.slide_stiffness_n_per_m3: expected a finite number >= 0, received {slide_k!r}")
        for i in idx:
            owner[int(i)] = k
            link_body_of[int(i)] = body  # a sliding point's body carries the lungs' wall over it too
            if slide_k > 0:
                slide_of[int(i)] = float(slide_k)
    link_vert = np.array(sorted(set(owner) - set(slide_of)), dtype=np.int32)
    slide_vert = np.array(sorted(slide_of), dtype=np.int32)
    _check_not_constrained(scene, mesh, regions, np.union1d(link_vert, slide_vert))

    # Body poses at qpos0 (to place the sites) and compiled inertias (to add masses).
    model0 = compile_spec(spec, label)
    body_names = [link_body_of[int(i)] for i in link_vert]
    site_names = [f"{rig.prefix}{_SITE_STEM}{int(i)}" for i in link_vert]
    taken = _taken_sites(spec, site_names)
    if taken:
        raise RigidError(
            f"rigid.prefix: site name(s) {taken[:3]} already exist in {label}; "
            f"choose another prefix than {rig.prefix!r}"
        )
    local = add_sites(spec, model0, body_names, mesh.vert_pos[link_vert], site_names, controls.key_id)
    slides = _slide_sites(spec, model0, rig.prefix, mesh, slide_vert, slide_of, link_body_of, controls.key_id)

    wall = _carried_sites(spec, model0, rig.prefix, carried, mesh.vert_pos, link_body_of, controls.key_id)

    link_mass = np.asarray(vert_mass, float)[link_vert]
    mass_added = np.zeros(link_vert.size, bool)
    if rig.add_link_mass:
        mass_added = np.array([n != "world" and model0.body(n).id != 0 for n in body_names])
        _add_point_masses(spec, model0, body_names, local, link_mass, mass_added)

    # MuJoCo keeps the MJCF's own timestep unless the scene sets dt_s
    system = CoupledRigid(
        spec,
        site_names,
        timestep=scene.dt_s,
        link_vert=link_vert,
        link_body=body_names,
        link_mass=link_mass,
        mass_added=mass_added,
        mjcf_path=source,
        controls=controls,
        ribs=ribs,
        wall=wall,
        slides=slides,
    )
    return system, link_vert


def _slide_sites(spec, model0, prefix: str, mesh, slide_vert, slide_of: dict, body_of: dict, key_id: int) -> dict:
    """A site per sliding point (`RigidLink.slide_stiffness_n_per_m3`) on its body, at the
    point's rest position, its z axis the membrane's rest normal there (the plane's normal,
    turned by the body as it moves: `site_xmat`'s third column), named
    f"{prefix}hybrid_slide_{i}". Returns {"site_names", "vert" (ns,) int32, "stiffness" (ns,)
    N/m: the link's stiffness times the point's share of the rest surface}."""
    vert = np.asarray(slide_vert, np.int32)
    names = [f"{prefix}hybrid_slide_{int(i)}" for i in vert]
    taken = _taken_sites(spec, names)
    if taken:
        raise RigidError(f"rigid.prefix: site name(s) {taken[:3]} already exist; choose another prefix than {prefix!r}")
    if not vert.size:
        return {"site_names": names, "vert": vert, "stiffness": np.zeros(0)}
    pos, face = np.asarray(mesh.vert_pos, float), np.asarray(mesh.face_vert, np.int64)
    cross = cross_rows(pos[face[:, 1]] - pos[face[:, 0]], pos[face[:, 2]] - pos[face[:, 0]])
    normal = scatter_corners(face, cross, cross, cross, len(pos))[vert]  # area-weighted vertex normals
    n = normal / np.linalg.norm(normal, axis=1)[:, None]
    bodies = [body_of[int(i)] for i in vert]
    add_sites(spec, model0, bodies, pos[vert], names, key_id)
    data0 = start_data(model0, key_id)
    for j, (b, name) in enumerate(zip(bodies, names)):
        rot = data0.xmat[model0.body(b).id].reshape(3, 3)
        spec.site(name).quat = _quat_z_to(rot.T @ n[j]).tolist()
    stiffness = np.array([slide_of[int(i)] for i in vert]) * vertex_area(pos, face)[vert]
    return {"site_names": names, "vert": vert, "stiffness": stiffness}


def _quat_z_to(n: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) turning the z axis onto unit vector n (the shortest turn)."""
    z = np.array([0.0, 0.0, 1.0])
    axis, c = np.cross(z, n), float(z @ n)
    if c < -1.0 + 1e-12:  # n = -z: half a turn about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    q = np.array([1.0 + c, *axis])
    return q / np.linalg.norm(q)


def _carried_sites(
    spec, model0, prefix: str, carried, vert_pos: np.ndarray, link_body_of: dict, key_id: int
) -> dict | None:
    """Sites for the carried points (`build_rigid`): a point over a linked (or sliding) membrane
    point follows `weight` of the displacement of that point's body at the membrane point's rest
    position (its site there): the wall between a rib and the fixed top follows the rib's
    border as a share of it, and does not swing with the rib's turn extended up to its own
    height (which took a point above the hinge inward as the rib rose). With a body pattern, the
    points strictly between the border and the top (weight in (0, 1)) also follow the nearest
    matching body (by its centre of mass where the model starts) by one minus their weight (and the
    top ring, weight 0, wholly when `Lungs.wall_top` is "carried"; the top's centre stays): the
    displacement of that body's point nearest to them (on its capsules' axes: the rib beside them;
    their own position for a body without capsules). Returns {"site_names", "point"
    (nc,) the carried points' indices (a point may appear twice), "weight" (nc,), "rest" (nc, 3)
    m the points' rest positions, "site_rest" (nc, 3) m their sites'}, or None."""
    if carried is None:
        return None
    pos, under, weight, pattern, top_carried = carried
    pos, weight = np.asarray(pos, float), np.asarray(weight, float)
    point = [j for j, i in enumerate(under) if int(i) in link_body_of and weight[j] > 0]
    names = [f"{prefix}hybrid_wall_{j}" for j in point]
    bodies = [link_body_of[int(under[j])] for j in point]
    shares = [float(weight[j]) for j in point]
    at = [np.asarray(vert_pos[int(under[j])], float) for j in point]
    if pattern is not None:
        all_bodies = [model0.body(i).name for i in range(1, model0.nbody)]
        chosen = [b for b in all_bodies if fnmatch.fnmatchcase(b, pattern)]
        if not chosen:
            raise RigidError(
                f"forces['lungs'].wall_bodies: no body of the rigid model matches {pattern!r}; "
                f"{close_names(pattern, all_bodies, 'body')}"
            )
        data0 = start_data(model0, key_id)
        com = data0.xipos[[model0.body(b).id for b in chosen]]
        # between the border and the top; with the top carried (`Lungs.wall_top`), its ring too
        between = (weight < 1) & ((weight > 0) | (top_carried & (np.asarray(under) >= 0)))
        for j in np.flatnonzero(between):
            near = chosen[int(np.argmin(np.linalg.norm(com - pos[j], axis=1)))]
            point.append(int(j))
            names.append(f"{prefix}hybrid_wall_up_{int(j)}")
            bodies.append(near)
            shares.append(1.0 - float(weight[j]))
            at.append(_nearest_on_capsules(model0, data0, model0.body(near).id, pos[j]))
    site_rest = np.asarray(at, float).reshape(-1, 3)
    add_sites(spec, model0, bodies, site_rest, names, key_id)
    idx = np.asarray(point, np.int64)
    return {
        "site_names": names,
        "point": idx,
        "weight": np.asarray(shares, float),
        "rest": pos[idx],
        "site_rest": site_rest,
    }


def _nearest_on_capsules(model, data, body: int, p: np.ndarray) -> np.ndarray:
    """The point of the body's capsules' axes nearest to p (3,) m, where the model starts (a rib
    drawn as capsules: the rib's point beside a wall point); p itself for a body without capsules."""
    best, best_d = np.asarray(p, float), np.inf
    for g in np.flatnonzero(model.geom_bodyid == body):
        if model.geom_type[g] != mujoco.mjtGeom.mjGEOM_CAPSULE:
            continue
        axis = data.geom_xmat[g].reshape(3, 3)[:, 2]
        half = float(model.geom_size[g, 1])
        c = data.geom_xpos[g]
        q = c + np.clip((p - c) @ axis, -half, half) * axis
        d = float(np.linalg.norm(q - p))
        if d < best_d:
            best, best_d = q, d
    return best


def _link_body(spec: mujoco.MjSpec, name) -> str | None:
    """The body a link names: a body, or the body that carries the named site."""
    if not isinstance(name, str) or not name:
        return None
    if spec.body(name) is not None:
        return name
    site = spec.site(name)
    if site is not None:
        return site.parent.name
    return None


def _check_not_constrained(scene: Scene, mesh, regions: dict, link_vert: np.ndarray) -> None:
    """Refuse a point both linked and nailed, prescribed or kept in a region (see
    hybrid.terms.base.claim_points), before MuJoCo compiles anything."""
    claims = [("linked", "rigid.links", link_vert)]
    for con in scene.constraints:
        if isinstance(con, (Nailed, Prescribed, KeepIn)):
            what = f"constraints[{con.name!r}].region"
            idx = _regions.select_on(con.region, mesh, name=what, regions=regions)
            kind = "keep_in" if isinstance(con, KeepIn) else type(con).__name__.lower()
            claim_points(claims[:1], idx, kind, what)


def _add_point_masses(
    spec: mujoco.MjSpec,
    model0: mujoco.MjModel,
    body_names: Sequence[str],
    local: np.ndarray,
    mass: np.ndarray,
    added: np.ndarray,
) -> None:
    """Add point masses (kg) at body-frame positions `local` (m) to their bodies.

    When the model takes every inertia from its geoms (`inertiafromgeom="true"`), each
    point becomes a tiny massive sphere geom that does not collide; otherwise the
    body's inertial is made explicit: its compiled mass, centre of mass and inertia
    combined with the points' (parallel-axis theorem).
    """
    by_body: dict[str, list[int]] = {}
    for j, name in enumerate(body_names):
        if added[j]:
            by_body.setdefault(name, []).append(j)
    from_geoms = spec.compiler.inertiafromgeom == _INERTIA_FROM_GEOM_TRUE
    for name, js in by_body.items():
        body = spec.body(name)
        if from_geoms:
            for j in js:
                body.add_geom(
                    name=f"{name}_{_SITE_STEM}mass_{j}",
                    size=[_POINT_GEOM_RADIUS, 0, 0],
                    pos=local[j].tolist(),
                    mass=float(mass[j]),
                    contype=0,
                    conaffinity=0,
                    group=5,
                    rgba=[0, 0, 0, 0],
                )
            continue
        bid = model0.body(name).id
        m_b = float(model0.body_mass[bid])
        c_b = model0.body_ipos[bid].copy()
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, model0.body_iquat[bid])
        rot = rot.reshape(3, 3)
        tensor = rot @ np.diag(model0.body_inertia[bid]) @ rot.T
        pts, mp = local[js], mass[js]
        m_tot = m_b + mp.sum()
        com = (m_b * c_b + (mp[:, None] * pts).sum(axis=0)) / m_tot

        def shifted(m, r):
            return m * (r @ r * np.eye(3) - np.outer(r, r))

        tensor = tensor + shifted(m_b, c_b - com)
        for p, m in zip(pts, mp):
            tensor = tensor + shifted(m, p - com)
        body.explicitinertial = True
        body.mass = float(m_tot)
        body.ipos = com.tolist()
        body.fullinertia = [tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2], tensor[1, 2]]
        body.inertia = [0.0, 0.0, 0.0]  # a diagonal inertia given by the MJCF would conflict (myotorso's)


def free_body_spec(
    mass: float,
    inertia: Sequence[float],
    point: Sequence[float],
    force: Sequence[float],
    *,
    integrator: str = "RK4",
    timestep: float = 1e-3,
) -> mujoco.MjSpec:
    """A single free rigid body, no gravity, no contact, pushed by a body-fixed point force.

    The body frame is its principal frame at the centre of mass, so that `qpos[0:3]`
    is the centre of mass and `qpos[3:7]` the orientation (w, x, y, z). The force is a
    `motor` actuator on a site at `point` whose gear is the force direction in the body
    frame: with `data.ctrl[0] = |force|` (N) MuJoCo itself evaluates the force within
    each step (at every stage of RK4), so the run converges at the integrator's own
    order. Set `ctrl` after compiling; it is 0 by default.

    Parameters
    ----------
    mass : kg (> 0).
    inertia : (3,) kg m^2, principal moments about the centre of mass.
    point : (3,) m, the point of application in the body frame.
    force : (3,) N, the force in the body frame.
    integrator : a MuJoCo integrator name ("Euler", "RK4", "implicit", "implicitfast").
    timestep : s.
    """
    f = np.asarray(force, dtype=float)
    fnorm = float(np.linalg.norm(f))
    spec = mujoco.MjSpec()
    spec.modelname = "free_body"
    spec.option.gravity = [0.0, 0.0, 0.0]
    spec.option.timestep = float(timestep)
    names = {
        "euler": "mjINT_EULER",
        "rk4": "mjINT_RK4",
        "implicit": "mjINT_IMPLICIT",
        "implicitfast": "mjINT_IMPLICITFAST",
    }
    if integrator.lower() not in names:
        raise RigidError(f"integrator: expected one of {sorted(names)}, got {integrator!r}")
    spec.option.integrator = getattr(mujoco.mjtIntegrator, names[integrator.lower()])
    body = spec.worldbody.add_body(
        name="body", mass=float(mass), inertia=[float(v) for v in inertia], explicitinertial=True
    )
    body.add_freejoint(name="free")
    body.add_site(name="push", pos=[float(v) for v in point])
    direction = f / fnorm if fnorm > 0 else np.array([1.0, 0.0, 0.0])
    act = spec.add_actuator(name="push", target="push", trntype=mujoco.mjtTrn.mjTRN_SITE)
    act.gear = [*direction.tolist(), 0.0, 0.0, 0.0]
    return spec
