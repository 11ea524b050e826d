"""A scene's body before its terms: its surface (`build_mesh`: a Mesh given, a mesh file
read, or a generator's sphere, refused when it is not a trunk's size) and the masses of
its points (`point_masses`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from . import checks
from . import regions as _regions
from .errors import MeshError, SceneError
from .mesh import Mesh, vertex_area
from .scene import MESH_GENERATORS, Masses, MeshSpec, Scene
from .terms.base import check_value

__all__ = ["LEVEL_GENERATORS", "MAX_BODY_M", "TRUNK_M", "build_mesh", "point_masses"]


#: the generators `mesh.level` refines
LEVEL_GENERATORS = ("uv_sphere", "ring_sphere", "fibonacci_sphere")


def _refine_file_mesh(pos, face, level):
    """A file mesh's faces split into four `level` times, the new points on the surface
    the file samples: its sphere, or the smooth surface through its points
    (`hybrid.mesh.refine.refine_file_mesh`, `MeshSpec`)."""
    from .mesh.refine import refine_file_mesh

    npoint = len(pos) + (4**level - 1) * len(face) // 2  # closed: E = 3F/2, F x 4 a level
    if npoint > checks.MAX_POINTS:  # before any array is allocated
        raise SceneError(
            f"mesh.level: level {level} splits the file mesh's {len(face)} faces into "
            f"{len(face) * 4**level} (about {npoint} points); expected at most {checks.MAX_POINTS} points"
        )
    try:
        pos, face, scheme = refine_file_mesh(pos, face, level, "mesh.level on a file mesh")
    except MeshError as exc:
        raise SceneError(str(exc)) from None
    return pos, face, scheme


#: the largest body a scene's membrane may be, across (m): a trunk is about 0.3 m, so a body
#: larger than this is a mesh drawn in millimetres or centimetres (300 m, 30 m across), or a
#: radius meant in millimetres, which would run and diverge at once
MAX_BODY_M = 10.0
#: a trunk's size across (m), what a refused size is compared with
TRUNK_M = 0.3


def build_mesh(scene: Scene) -> Mesh:
    """The scene's surface: a given Mesh, a mesh file, or a generator; refused in one line
    when it is more than MAX_BODY_M across (`_check_body_size`)."""
    mesh = _build_mesh(scene)
    _check_body_size(mesh, scene.mesh)
    return mesh


def _check_body_size(mesh: Mesh, spec) -> None:
    """SceneError naming the culprit (the file and its unit_scale, radius_m, or the Mesh
    given) and a scale that would make the body a trunk's size, when the body is more
    than MAX_BODY_M across (the largest side of its bounding box)."""
    across = float(np.ptp(mesh.vert_pos, axis=0).max())
    if across <= MAX_BODY_M:
        return
    # the unit the numbers were likely meant in: the one that makes the body closest to a trunk
    unit, per_m = min(
        (("millimetres", 1e-3), ("centimetres", 1e-2)), key=lambda u: abs(math.log(across * u[1] / TRUNK_M))
    )
    plausible = f"expected a body at most {MAX_BODY_M:g} m across (a trunk is about {TRUNK_M:g} m)"
    if isinstance(spec, MeshSpec) and spec.path is not None:
        scale = spec.unit_scale
        raise SceneError(
            f"mesh file {str(spec.path)!r}: a body {across:.4g} m across at mesh.unit_scale = {scale:g} m per file "
            f"unit; {plausible}; a file in {unit}? set mesh.unit_scale = {scale * per_m:g} ({across * per_m:.3g} m)"
        )
    if isinstance(spec, MeshSpec):
        raise SceneError(
            f"mesh.radius_m: a body {across:.4g} m across (radius_m = {spec.radius_m:g}); {plausible}; a radius in "
            f"{unit}? set mesh.radius_m = {spec.radius_m * per_m:g}"
        )
    raise SceneError(
        f"mesh: the Mesh {mesh.name!r} is a body {across:.4g} m across; {plausible}; positions in {unit}? "
        f"scale its vert_pos by {per_m:g}"
    )


def _build_mesh(scene: Scene) -> Mesh:
    from . import mesh as _mesh

    spec = scene.mesh
    if isinstance(spec, Mesh):
        return spec
    if not isinstance(spec, MeshSpec):
        raise SceneError(f"mesh: expected a MeshSpec or a hybrid.mesh.Mesh, received {type(spec).__name__}")
    # each field checked by the kind MeshSpec gives it (the scene file reads the same);
    # the generator by the choice below, whose message also offers a path
    val = {
        f.name: check_value(f"mesh.{f.name}", f.metadata["kind"], getattr(spec, f.name), f.metadata)
        for f in dataclasses.fields(MeshSpec)
        if getattr(spec, f.name) is not None and f.name != "generator"
    }
    center = np.asarray(val["center_m"])
    if spec.path is not None:
        m = Mesh.load(scene.resolve(spec.path))
        pos, face = m.vert_pos * val["unit_scale"] + center, m.face_vert
        level = val.get("level") or 0
        if not level:
            return Mesh.from_arrays(pos, face, name=m.name)
        from .mesh.refine import refinement_of

        coarse = pos
        pos, face, scheme = _refine_file_mesh(pos, face, level)
        # regions given on the file's points (`Indices`) carry to the new ones through it; on
        # the smooth surface through a file's points (not a sphere's), regions of geometry too
        ref = refinement_of(coarse, m.face_vert, level, carry_geometry=scheme == "loop")
        return Mesh.from_arrays(pos, face, name=f"{m.name}_level{level}", refinement=ref)
    radius = val["radius_m"]
    gen = spec.generator
    if val.get("level") is not None and gen not in LEVEL_GENERATORS:
        raise SceneError(
            f"mesh.level: expected a generator that refines by level ({', '.join(LEVEL_GENERATORS)}), "
            f"received generator={gen!r}"
        )
    for key, what in (("conform_z_m", "latitudes"), ("conform_azimuth_deg", "azimuths")):
        if val.get(key) and gen not in ("uv_sphere", "ring_sphere"):
            raise SceneError(
                f"mesh.{key}: expected a generator with circles of latitude (uv_sphere or "
                f"ring_sphere), received generator={gen!r}; or no {what} (--set mesh.{key}=[])"
            )
    conform, azimuths = val.get("conform_z_m", ()), val.get("conform_azimuth_deg", ())
    npoint = _mesh.level_counts(val.get("level") or 0)[2]
    try:
        if gen == "fibonacci_sphere":
            return _mesh.fibonacci_sphere(npoint, radius, center=tuple(center))
        if gen == "ring_sphere":
            return _mesh.ring_sphere(
                npoint, radius, center=tuple(center), conform_z=conform, conform_azimuth_deg=azimuths
            )
    except MeshError as exc:
        raise SceneError(f"mesh: {exc}") from None
    if gen == "uv_sphere":
        if val.get("level") is not None:
            val["segments"], val["rings"], _ = _mesh.level_counts(val["level"])
        npoint = val["segments"] * (val["rings"] - 1) + 2
        if npoint > checks.MAX_POINTS:  # before any array is allocated
            raise SceneError(
                f"mesh: segments = {val['segments']} x rings = {val['rings']} gives {npoint} points; "
                f"expected at most {checks.MAX_POINTS}"
            )
        try:
            return _mesh.uv_sphere(
                radius,
                val["segments"],
                val["rings"],
                center=tuple(center),
                conform_z=conform,
                conform_azimuth_deg=azimuths,
            )
        except MeshError as exc:
            raise SceneError(f"mesh: {exc}") from None
    if gen == "icosphere":
        return _mesh.icosphere(val["subdivisions"], radius, center=tuple(center))
    if gen == "icosahedron":
        return _mesh.icosahedron(radius, center=tuple(center))
    raise SceneError(f"mesh: expected a path or a generator in {list(MESH_GENERATORS)}, received generator={gen!r}")


def point_masses(spec: Masses, mesh: Mesh, regions: dict) -> np.ndarray:
    given = [k for k in ("total_kg", "density_kg_per_m2", "per_vertex_kg") if getattr(spec, k) is not None]
    if len(given) != 1:
        raise SceneError(
            f"masses: expected exactly one of total_kg, density_kg_per_m2, per_vertex_kg, received {given or 'none'}"
        )
    area = vertex_area(mesh.vert_pos, mesh.face_vert)
    if spec.total_kg is not None:
        total = checks.positive("masses.total_kg", spec.total_kg, checks.MAX_MASS_KG, " kg")
        return total * area / area.sum()
    if spec.per_vertex_kg is not None:
        m = np.asarray(spec.per_vertex_kg, dtype=float)
        if m.shape != (mesh.nvert,):
            raise SceneError(f"masses.per_vertex_kg: expected {mesh.nvert} values, received shape {m.shape}")
        bad = np.nonzero(~(m > 0) | ~np.isfinite(m))[0]
        if bad.size:
            raise SceneError(
                f"masses.per_vertex_kg: expected masses > 0 kg, received {float(m[bad[0]])!r} "
                f"at vertices {bad[:8].tolist()}"
            )
        bad = np.nonzero(m > checks.MAX_MASS_KG)[0]
        if bad.size:
            raise SceneError(
                f"masses.per_vertex_kg: expected masses > 0 kg and <= {checks.MAX_MASS_KG:g} kg "
                f"(a physical bound), received {float(m[bad[0]])!r} at vertices {bad[:8].tolist()}"
            )
        return m.copy()
    dens = spec.density_kg_per_m2
    if not isinstance(dens, dict) or not dens:
        raise SceneError(f"masses.density_kg_per_m2: expected {{region: kg/m^2}}, received {dens!r}")
    m = np.full(mesh.nvert, np.nan)
    for name, rho in dens.items():
        rho = checks.positive(f"masses.density_kg_per_m2[{name!r}]", rho, checks.MAX_MASS_KG, " kg/m^2")
        idx = _regions.select_on(name, mesh, name=f"masses.density_kg_per_m2[{name!r}]", regions=regions)
        m[idx] = rho * area[idx]
    missing = np.nonzero(np.isnan(m))[0]
    if missing.size:
        raise SceneError(
            f"masses.density_kg_per_m2: vertices {missing[:8].tolist()} ({missing.size} in all) "
            f"lie in none of the regions {list(dens)}; expected every vertex covered"
        )
    return m
