"""Compiling a scene (hybrid.model.compile_scene): every bad input of a scene raises its
error, and the message names the culprit (the argument or element at fault), what was
expected and what was received. Mesh construction errors are tested in
tests/mesh/test_validate.py; here only the mesh errors that come from a scene (generator
spec, volume on an open surface, degenerate shape-memory rings). And what the compiled
model leaves out: the forces of nailed points."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import BASE, base_scene, open_hemisphere, with_constraint, with_force

from hybrid.errors import HybridError, MeshError, SceneError
from hybrid.mesh import Mesh
from hybrid.model import compile_scene
from hybrid.regions import All, Ball, Box, Difference, HalfSpace, Indices, Nearest
from hybrid.scene import (
    AppliedForce,
    Attraction,
    Damping,
    Gravity,
    KeepIn,
    Masses,
    MassSpring,
    MeshSpec,
    Muscle,
    Nailed,
    Prescribed,
    ShapeMemory,
    SoftVolume,
    Volume,
)
from hybrid.schedule import Breathing, Table


def test_the_base_scene_compiles():
    assert compile_scene(BASE).terms == ("gravity", "damping", "shape_memory", "volume")


# Each case: (id, scene factory, error class, regex the message must contain).
# The regexes name the culprit and, where the message gives them, the expected
# and received values.
CASES = [
    # -- the scene itself
    ("scene_type", lambda: "scene.toml", SceneError, r"scene: expected a hybrid\.scene\.Scene, received str"),
    ("dt_zero", lambda: base_scene(dt_s=0.0), SceneError, r"dt_s: expected a time step > 0 s, received 0\.0"),
    ("dt_negative", lambda: base_scene(dt_s=-1e-3), SceneError, r"dt_s: .*> 0 s, received -0\.001"),
    ("dt_nan", lambda: base_scene(dt_s=math.nan), SceneError, r"dt_s: .*received nan"),
    ("dt_string", lambda: base_scene(dt_s="1e-3"), SceneError, r"dt_s: .*received '1e-3'"),
    (
        "integrator",
        lambda: base_scene(integrator="rk4"),
        SceneError,
        r"integrator: expected one of \['explicit_euler', 'symplectic_euler', 'implicit_euler'\], received 'rk4'",
    ),
    (
        "duplicate_names",
        lambda: with_force(ShapeMemory(100.0, region="top")),
        SceneError,
        r"terms: expected unique names, received \['shape_memory'\]",
    ),
    (
        "unknown_force",
        lambda: with_force(Nailed("top", name="nail_top")),
        SceneError,
        r"forces: expected Gravity.*received Nailed",
    ),
    (
        "force_not_a_term",
        lambda: base_scene(forces=("gravity",)),
        SceneError,
        r"forces: expected Gravity.*received str",
    ),
    (
        "constraint_not_a_term",
        lambda: base_scene(constraints=({"volume": True},)),
        SceneError,
        r"constraints: expected Nailed.*received dict",
    ),
    (
        "unknown_constraint",
        lambda: with_constraint(Gravity(name="g2")),
        SceneError,
        r"constraints: expected Nailed.*received Gravity",
    ),
    # -- mesh specs
    (
        "mesh_generator",
        lambda: base_scene(mesh=MeshSpec(generator="torus")),
        SceneError,
        r"mesh: expected a path or a generator in .*received generator='torus'",
    ),
    ("mesh_radius", lambda: base_scene(mesh=MeshSpec(radius_m=-0.1)), SceneError, r"mesh\.radius_m: .*received -0\.1"),
    (
        "mesh_subdivisions",
        lambda: base_scene(mesh=MeshSpec(generator="icosphere", subdivisions=12)),
        SceneError,
        r"mesh\.subdivisions: expected an integer in 0\.\.7, received 12",
    ),
    (
        "mesh_segments",
        lambda: base_scene(mesh=MeshSpec(segments=2)),
        SceneError,
        r"mesh\.segments: expected an integer >= 3, received 2",
    ),
    (
        "mesh_type",
        lambda: base_scene(mesh=np.zeros((3, 3))),
        SceneError,
        r"mesh: expected a MeshSpec .*received ndarray",
    ),
    (
        "mesh_file_missing",
        lambda: base_scene(mesh=MeshSpec(path="/nonexistent/abdomen.stl")),
        MeshError,
        r"abdomen\.stl.*does not exist",
    ),
    # -- masses (point 3)
    (
        "masses_none",
        lambda: base_scene(masses=Masses()),
        SceneError,
        r"masses: expected exactly one of total_kg, density_kg_per_m2, per_vertex_kg, received none",
    ),
    (
        "masses_two",
        lambda: base_scene(masses=Masses(total_kg=4.0, per_vertex_kg=(0.05,) * 80)),
        SceneError,
        r"masses: expected exactly one of .*received \['total_kg', 'per_vertex_kg'\]",
    ),
    (
        "masses_negative_total",
        lambda: base_scene(masses=Masses(total_kg=-4.0)),
        SceneError,
        r"masses\.total_kg: expected a number > 0, received -4\.0",
    ),
    (
        "masses_zero_total",
        lambda: base_scene(masses=Masses(total_kg=0.0)),
        SceneError,
        r"masses\.total_kg: .*received 0\.0",
    ),
    (
        "masses_wrong_length",
        lambda: base_scene(masses=Masses(per_vertex_kg=(0.05,) * 79)),
        SceneError,
        r"masses\.per_vertex_kg: expected 80 values, received shape \(79,\)",
    ),
    (
        "masses_negative_vertex",
        lambda: base_scene(masses=Masses(per_vertex_kg=(0.05,) * 3 + (-0.05,) + (0.05,) * 76)),
        SceneError,
        r"masses\.per_vertex_kg: expected masses > 0 kg, received -0\.05 at vertices \[3\]",
    ),
    (
        "masses_nan_vertex",
        lambda: base_scene(masses=Masses(per_vertex_kg=(math.nan,) + (0.05,) * 79)),
        SceneError,
        r"masses\.per_vertex_kg: .*at vertices \[0\]",
    ),
    (
        "density_not_covering",
        lambda: base_scene(masses=Masses(density_kg_per_m2={"top": 20.0, "bottom": 20.0})),
        SceneError,
        r"masses\.density_kg_per_m2: vertices \[.*\] \(\d+ in all\) lie in none of the regions \['top', 'bottom'\]",
    ),
    (
        "density_unknown_region",
        lambda: base_scene(masses=Masses(density_kg_per_m2={"belly": 20.0})),
        SceneError,
        r"refers to region 'belly', which is not defined",
    ),
    (
        "density_negative",
        lambda: base_scene(masses=Masses(density_kg_per_m2={"all": -20.0})),
        SceneError,
        r"masses\.density_kg_per_m2\['all'\]: expected a number > 0, received -20\.0",
    ),
    (
        "density_type",
        lambda: base_scene(masses=Masses(density_kg_per_m2=20.0)),
        SceneError,
        r"masses\.density_kg_per_m2: expected \{region: kg/m\^2\}, received 20\.0",
    ),
    # -- regions (point 4)
    (
        "region_selects_nothing",
        lambda: base_scene(regions={**BASE.regions, "lid": HalfSpace((0, 0, 1.0), (0, 0, 1))}),
        SceneError,
        r"region 'lid': expected at least one vertex, the selector .* selects none of the 80 vertices",
    ),
    (
        "region_unknown_name",
        lambda: with_force(Attraction("belly", 10.0)),
        SceneError,
        r"forces\['attraction'\]\.region.*refers to region 'belly', which is not defined; defined regions: "
        r"\['bottom', 'top', 'all'\]",
    ),
    (
        "region_index_out_of_range",
        lambda: base_scene(regions={**BASE.regions, "spine": Indices((0, 80, 95))}),
        SceneError,
        r"region 'spine': vertex indices must lie in \[0, 80\), received \[80, 95\]",
    ),
    (
        "region_index_negative",
        lambda: base_scene(regions={**BASE.regions, "spine": Indices((-1, 3))}),
        SceneError,
        r"region 'spine': vertex indices must lie in \[0, 80\), received \[-1\]",
    ),
    (
        "region_index_float",
        lambda: base_scene(regions={**BASE.regions, "spine": Indices((0.5, 3.0))}),
        SceneError,
        r"region 'spine': expected a list of vertex indices, received \(0\.5, 3\.0\)",
    ),
    (
        "region_not_a_selector",
        lambda: base_scene(regions={**BASE.regions, "spine": 42}),
        SceneError,
        r"region 'spine': expected a selector .*received 42",
    ),
    (
        "region_half_space_zero_normal",
        lambda: base_scene(regions={**BASE.regions, "x": HalfSpace((0, 0, 0), (0, 0, 0))}),
        SceneError,
        r"region 'x'\.normal: expected a non-zero vector",
    ),
    (
        "region_half_space_bad_point",
        lambda: base_scene(regions={**BASE.regions, "x": HalfSpace((0, 0), (0, 0, 1))}),
        SceneError,
        r"region 'x'\.point: expected a 3-vector of finite floats, received \(0, 0\)",
    ),
    (
        "region_ball_radius",
        lambda: base_scene(regions={**BASE.regions, "x": Ball((0, 0, 0), -1.0)}),
        SceneError,
        r"region 'x'\.radius: expected > 0 m, received -1\.0",
    ),
    (
        "region_box_inverted",
        lambda: base_scene(regions={**BASE.regions, "x": Box((1, 1, 1), (0, 0, 0))}),
        SceneError,
        r"region 'x': expected lo <= hi componentwise",
    ),
    (
        "region_nearest_bad",
        lambda: base_scene(regions={**BASE.regions, "x": Nearest(((0, 0),))}),
        SceneError,
        r"region 'x'\.points: expected a list of 3-vectors",
    ),
    (
        "region_difference_empty",
        lambda: base_scene(regions={**BASE.regions, "x": Difference(All(), All())}),
        SceneError,
        r"region 'x': expected at least one vertex",
    ),
    # -- forces (point 5)
    (
        "shape_memory_negative",
        lambda: base_scene(forces=(ShapeMemory(-3000.0),)),
        SceneError,
        r"forces\['shape_memory'\]\.stiffness_n_per_m: expected a number > 0, received -3000\.0",
    ),
    (
        "mass_spring_zero",
        lambda: with_force(MassSpring(0.0)),
        SceneError,
        r"forces\['mass_spring'\]\.stiffness_n_per_m: expected a number > 0, received 0\.0",
    ),
    (
        "attraction_negative",
        lambda: with_force(Attraction("top", -5.0)),
        SceneError,
        r"forces\['attraction'\]\.stiffness_n_per_m: .*received -5\.0",
    ),
    (
        "attraction_target_shape",
        lambda: with_force(Attraction("top", 5.0, target_m=((0, 0, 0), (1, 1, 1)))),
        SceneError,
        r"forces\['attraction'\]\.target_m: expected a 3-vector or \d+ 3-vectors, received shape \(2, 3\)",
    ),
    (
        "attraction_offset_vector",
        lambda: with_force(Attraction("top", 5.0, offset_m=(0.0, 0.01))),
        SceneError,
        r"forces\['attraction'\]\.offset_m: expected a 3-vector of finite floats, received \(0\.0, 0\.01\)",
    ),
    (
        "soft_volume_negative",
        lambda: with_force(SoftVolume(-1.0)),
        SceneError,
        r"forces\['soft_volume'\]\.stiffness_n_per_m: .*received -1\.0",
    ),
    (
        "gravity_short_vector",
        lambda: base_scene(forces=(Gravity((0.0, -9.81)),)),
        SceneError,
        r"forces\['gravity'\]\.accel_m_s2: expected a 3-vector of finite floats, received \(0\.0, -9\.81\)",
    ),
    (
        "gravity_nan",
        lambda: base_scene(forces=(Gravity((0.0, 0.0, math.nan)),)),
        SceneError,
        r"forces\['gravity'\]\.accel_m_s2: expected a 3-vector",
    ),
    (
        "applied_force_vector",
        lambda: with_force(AppliedForce("top", (1.0, 2.0, 3.0, 4.0))),
        SceneError,
        r"forces\['applied_force'\]\.force_n: expected a 3-vector of finite floats, received \(1\.0, 2\.0, 3\.0, 4\.0\)",
    ),
    (
        "applied_force_string",
        lambda: with_force(AppliedForce("top", "up")),
        SceneError,
        r"forces\['applied_force'\]\.force_n: expected a 3-vector of finite floats, received 'up'",
    ),
    (
        "muscle_both_directions",
        lambda: with_force(Muscle("top", 100.0, toward_m=(0, 0, 0.12), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]: expected exactly one fibre direction, toward_m or axis, received "
        r"toward_m=\(0, 0, 0\.12\) axis=\(0, 0, 1\)",
    ),
    (
        "muscle_no_direction",
        lambda: with_force(Muscle("top", 100.0)),
        SceneError,
        r"forces\['muscle'\]: expected exactly one fibre direction.*toward_m=None axis=None",
    ),
    (
        "muscle_zero_axis",
        lambda: with_force(Muscle("top", 100.0, axis=(0, 0, 0))),
        SceneError,
        r"forces\['muscle'\]\.axis: expected a non-zero vector",
    ),
    (
        "muscle_bad_angle",
        lambda: with_force(Muscle("top", 100.0, axis=(0, 0, 1), max_angle_deg=90.0)),
        SceneError,
        r"forces\['muscle'\]\.max_angle_deg: expected a number in \(0, 90\), received 90\.0",
    ),
    # the north pole's chords to its ring run ~77 deg off the z axis
    (
        "muscle_no_neighbour",
        lambda: with_force(Muscle(Indices((0,)), 100.0, axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]: no neighbour lies within 30\.0 deg of the fibre direction",
    ),
    (
        "muscle_stiffness_vector",
        lambda: with_force(Muscle("top", (1.0, 2.0, 3.0), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness: expected a number of finite floats, received \(1\.0, 2\.0, 3\.0\)",
    ),
    (
        "damping_without_stiffness",
        lambda: base_scene(forces=(Gravity(), Damping(critical_fraction=0.3))),
        SceneError,
        r"forces\['damping'\]\.critical_fraction: vertices \[.*\] have no elastic stiffness .*give coef_n_s_per_m",
    ),
    (
        "damping_partly_without_stiffness",
        lambda: base_scene(forces=(ShapeMemory(3000.0, region="top"), Damping(critical_fraction=0.3))),
        SceneError,
        r"forces\['damping'\]\.critical_fraction: vertices \[27, 28, .*\] have no elastic stiffness",
    ),
    (
        "damping_both",
        lambda: base_scene(forces=(ShapeMemory(3000.0), Damping(coef_n_s_per_m=1.0, critical_fraction=0.3))),
        SceneError,
        r"forces\['damping'\]: expected exactly one of drag_n_s_per_m3, coef_n_s_per_m or critical_fraction",
    ),
    (
        "damping_neither",
        lambda: base_scene(forces=(ShapeMemory(3000.0), Damping())),
        SceneError,
        r"forces\['damping'\]: expected exactly one of .*coef_n_s_per_m=None critical_fraction=None",
    ),
    (
        "damping_negative",
        lambda: base_scene(forces=(ShapeMemory(3000.0), Damping(coef_n_s_per_m=-1.0))),
        SceneError,
        r"forces\['damping'\]\.coef_n_s_per_m: expected a number >= 0, received -1\.0",
    ),
    (
        "shape_memory_degenerate_ring",
        lambda: base_scene(
            mesh=Mesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], name="triangle"),
            masses=Masses(total_kg=1.0),
            regions={},
            forces=(ShapeMemory(10.0),),
            constraints=(),
        ),
        MeshError,
        r"shape memory: vertices \[0, 1, 2\] \(3 in all\) have a degenerate neighbour ring",
    ),
    # -- integrator (point 6): see "integrator" above
    # -- constraints (point 7)
    (
        "volume_on_open_mesh",
        lambda: base_scene(mesh=open_hemisphere(), regions={}, constraints=(Volume(),)),
        MeshError,
        r"constraints\['volume'\]: a constant-volume constraint needs a closed surface; mesh 'hemisphere' is open: "
        r"13 border edges",
    ),
    (
        "soft_volume_on_open_mesh",
        lambda: base_scene(mesh=open_hemisphere(), regions={}, forces=(SoftVolume(1e4),), constraints=()),
        MeshError,
        r"forces\['soft_volume'\] \(compressible volume\) needs a closed surface; mesh 'hemisphere' is open",
    ),
    (
        "everything_nailed_with_volume",
        lambda: base_scene(constraints=(Nailed("all"), Volume())),
        SceneError,
        r"constraints\['volume'\]: every point is nailed, prescribed or linked; expected at least one free point",
    ),
    (
        "keep_in_bad_shape",
        lambda: with_constraint(KeepIn("top", "cylinder")),
        SceneError,
        r"constraints\['keep_in'\]\.shape: expected 'half_space', 'ball' or 'box', received 'cylinder'",
    ),
    (
        "keep_in_ball_no_radius",
        lambda: with_constraint(KeepIn("top", "ball", center_m=(0, 0, 0))),
        SceneError,
        r"constraints\['keep_in'\]\.radius_m: expected a number > 0, received None",
    ),
    (
        "keep_in_ball_no_center",
        lambda: with_constraint(KeepIn("top", "ball", radius_m=0.2)),
        SceneError,
        r"constraints\['keep_in'\]\.center_m: expected a 3-vector of finite floats, received None",
    ),
    (
        "keep_in_half_space_zero_normal",
        lambda: with_constraint(KeepIn("top", "half_space", point_m=(0, 0, 0), normal=(0, 0, 0))),
        SceneError,
        r"constraints\['keep_in'\]\.normal: expected a non-zero vector",
    ),
    (
        "keep_in_box_inverted",
        lambda: with_constraint(KeepIn("top", "box", lo_m=(0, 0, 0), hi_m=(1, 0, 1))),
        SceneError,
        r"constraints\['keep_in'\]: expected lo_m < hi_m componentwise",
    ),
    (
        "keep_in_unknown_region",
        lambda: with_constraint(KeepIn("belly", "box", lo_m=(0, 0, 0), hi_m=(1, 1, 1))),
        SceneError,
        r"constraints\['keep_in'\]\.region.*refers to region 'belly'",
    ),
    (
        "nailed_unknown_region",
        lambda: base_scene(constraints=(Nailed("spine"), Volume())),
        SceneError,
        r"constraints\['nailed'\]\.region.*refers to region 'spine'",
    ),
    (
        "prescribed_vector",
        lambda: with_constraint(Prescribed("top", (0.0, 0.01))),
        SceneError,
        r"constraints\['prescribed'\]\.displacement_m: expected a 3-vector of finite floats, received \(0\.0, 0\.01\)",
    ),
    # -- schedules (point 5's functions of time and 7's trajectories)
    (
        "table_times_not_increasing",
        lambda: with_force(Muscle("top", Table((0.0, 1.0, 1.0), (0.0, 5.0, 0.0)), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness\.t_s: expected strictly increasing times, received \[0\.0, 1\.0, 1\.0\]",
    ),
    (
        "table_times_decreasing",
        lambda: with_constraint(Prescribed("top", Table((1.0, 0.0), ((0, 0, 0), (0, 0, 1))))),
        SceneError,
        r"constraints\['prescribed'\]\.displacement_m\.t_s: expected strictly increasing times",
    ),
    (
        "table_value_count",
        lambda: with_force(Muscle("top", Table((0.0, 1.0, 2.0), (0.0, 5.0)), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness\.value: expected 3 values \(one per time\), received 2",
    ),
    (
        "table_value_size",
        lambda: with_force(AppliedForce("top", Table((0.0, 1.0), ((0, 0, 1), (0, 1))))),
        SceneError,
        r"forces\['applied_force'\]\.force_n\.value: expected a 3-vector of finite floats, received \(0, 1\)",
    ),
    (
        "table_scalar_for_vector",
        lambda: with_force(AppliedForce("top", Table((0.0, 1.0), (0.0, 1.0)))),
        SceneError,
        r"forces\['applied_force'\]\.force_n\.value: expected a 3-vector",
    ),
    (
        "table_empty",
        lambda: with_force(Muscle("top", Table((), ()), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness\.t_s: expected a non-empty list of finite times",
    ),
    (
        "table_periodic_one_sample",
        lambda: with_force(Muscle("top", Table((0.0,), (5.0,), periodic=True), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness: a periodic table needs at least 2 samples, received 1",
    ),
    (
        "breathing_as_vector",
        lambda: with_force(AppliedForce("top", Breathing())),
        SceneError,
        r"forces\['applied_force'\]\.force_n: a breathing waveform is scalar",
    ),
    (
        "breathing_as_trajectory",
        lambda: with_constraint(Prescribed("top", Breathing())),
        SceneError,
        r"constraints\['prescribed'\]\.displacement_m: a breathing waveform is scalar",
    ),
    (
        "breathing_fraction",
        lambda: with_force(Muscle("top", Breathing(inspiration_fraction=1.5), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness\.inspiration_fraction: expected in \(0, 1\), received 1\.5",
    ),
    (
        "breathing_fraction_zero",
        lambda: with_force(Muscle("top", Breathing(inspiration_fraction=0.0), axis=(0, 0, 1))),
        SceneError,
        r"inspiration_fraction: expected in \(0, 1\), received 0\.0",
    ),
    (
        "breathing_period",
        lambda: with_force(Muscle("top", Breathing(period_s=0.0), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness\.period_s: expected > 0, received 0\.0",
    ),
    (
        "breathing_peak",
        lambda: with_force(Muscle("top", Breathing(peak=math.inf), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness\.peak: expected a finite number, received inf",
    ),
    (
        "breathing_onset",
        lambda: with_force(Muscle("top", Breathing(onset_s=-1.0), axis=(0, 0, 1))),
        SceneError,
        r"forces\['muscle'\]\.stiffness\.onset_s: expected >= 0, received -1\.0",
    ),
]


@pytest.mark.parametrize("make,error,pattern", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_raises_a_named_error(make, error, pattern):
    with pytest.raises(error, match=pattern) as info:
        compile_scene(make())
    assert isinstance(info.value, HybridError)
    assert "\n" not in str(info.value)  # one line, for the command line


def test_model_with_a_bad_time_step():
    model = compile_scene(BASE)
    with pytest.raises(SceneError, match=r"dt_s: expected a time step > 0 s, received -0\.001"):
        model.with_dt(-1e-3)
    with pytest.raises(SceneError, match=r"integrator: expected one of .*received 'leapfrog'"):
        model.with_dt(1e-3, "leapfrog")


def test_forces_of_nailed_points_are_never_computed():
    """Nailed points never move, so no force term computes anything for them
    (the other tests with nailed points show the motion is unchanged)."""
    from hybrid.demo import membrane_demo

    model = compile_scene(membrane_demo())
    nailed = np.flatnonzero(model.arrays.vert_free == 0)
    assert nailed.size > 0
    assert not np.isin(model.arrays.sm_vert, nailed).any()
    assert not np.isin(model.arrays.mus_vert, nailed).any()
    assert model.arrays.sm_vert.size == model.nvert - nailed.size
