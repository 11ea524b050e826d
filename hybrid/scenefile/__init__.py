"""Scene files: TOML with the same fields as the `hybrid.scene` dataclasses.

`load_scene(path)` reads a file into a `Scene` (relative paths in it resolve in the
file's folder); `scene_from_dict` does the same for an already parsed mapping and
`scene_to_dict` goes back. Validation is strict and every error is a `SceneError`
with one line naming the file and the key path, e.g.
``breathing.toml: forces[2].stiffness_n_per_m: expected a number > 0, received -3``.

The format (SI units; every key optional unless marked *required*)::

    name = "breathing"            # top level: name, formulation, dt_s, integrator, duration_s
    formulation = "paper"         # or "continuum" (the default): what the parameters mean
    dt_s = 1e-3
    integrator = "symplectic_euler"    # or "explicit_euler", "implicit_euler"
    duration_s = 12.0

    [mesh]          # generator = "uv_sphere" | "icosphere" | "icosahedron", or path = "file.stl"
    generator = "uv_sphere"            # radius_m, segments, rings, subdivisions, center_m, unit_scale
    [masses]        # exactly one of: total_kg, density_kg_per_m2 = {region = kg/m^2}, per_vertex_kg = [..]
    total_kg = 4.0

    [regions]       # name = selector, evaluated in order; a later region may name an earlier one
    top = { half_space = { point = [0, 0, 0.07], normal = [0, 0, 1] } }
    #  selectors: "all" | "REGION NAME" | { border = true } | { indices = [0, 5] }
    #    | { half_space = { point, normal } } | { ball = { center, radius } } | { box = { lo, hi } }
    #    | { nearest = [[x, y, z], ...] } | { patch = { center, radius_m } } (a disc of the surface,
    #    its area checked) | { union = [sel, ...] } | { intersection = [sel, ...] }
    #    | { difference = { base = sel, minus = sel } }

    [[forces]]      # type = gravity | damping | shape_memory | mass_spring | muscle
    type = "muscle" #        | applied_force | attraction | soft_volume | pressure | muscle_fibres;
                    #        name defaults to type
    region = "top"
    stiffness = { breathing = { period_s = 4.0, inspiration_fraction = 0.4, peak = 60.0 } }
    toward_m = [0, 0, 0.12]
    #  schedules: a number or [x, y, z] (constant) | { breathing = { period_s, inspiration_fraction,
    #    peak, onset_s } } | { table = { t_s = [..], value = [..], periodic = false } }

    [[constraints]] # type = nailed | keep_in | prescribed | volume
    type = "volume"

    [rigid]         # mjcf (required): "trunk" (the packaged model) or a path; prefix; add_link_mass;
    mjcf = "trunk"  #   keyframe, fix, fix_root, weld, hold, lock, ctrl, integrator, load_joints,
                    #   [rigid.ribs] with [[rigid.ribs.pairs]] (hybrid.rigidfile)
    [[rigid.links]] # region and body required; name defaults to the body's
    region = "ribs"
    body = "rib_left"

Overrides (`apply_overrides`, the command line's ``--set KEY=VALUE``): KEY is a
dotted path in this TOML structure; an element of `forces`, `constraints` or
`rigid.links` is chosen by its `name` (which defaults to its type) or by its
index; VALUE is a TOML value (a bare word is taken as a string). Examples:
``dt_s=5e-4``, ``forces.muscle.stiffness.breathing.peak=80``,
``forces.2.region=all``, ``mesh.radius_m=0.1``, ``rigid.links.rib_left.body=spine``.
"""

from __future__ import annotations

# the `X as X` names: re-exported for tests/test_scenefile*.py and hybrid.docgen
from ..terms import CONSTRAINT_TYPES as CONSTRAINT_TYPES
from ..terms import FORCE_TYPES as FORCE_TYPES
from .overrides import apply_overrides
from .packaged import builtin_scene, builtin_scenes, packaged_model
from .read import _SELECTOR_KINDS as _SELECTOR_KINDS
from .read import _TOP as _TOP
from .read import load_scene, scene_from_dict
from .write import scene_to_dict, scene_to_toml

__all__ = [
    "load_scene",
    "scene_from_dict",
    "scene_to_dict",
    "scene_to_toml",
    "apply_overrides",
    "builtin_scene",
    "packaged_model",
    "builtin_scenes",
]
