"""Property: any scene the vocabulary can express survives the scene file,
Scene -> TOML text -> Scene, field for field (and the text is stable)."""

from __future__ import annotations

import tomllib

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hybrid import regions as R
from hybrid import scenefile as sf
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
    MuscleFibres,
    Nailed,
    Prescribed,
    Pressure,
    Rigid,
    RigidLink,
    Scene,
    ShapeMemory,
    SoftVolume,
    Volume,
)
from hybrid.schedule import Breathing, Constant, Table

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
# within every field's physical bounds (hybrid.checks): sizes and steps up to 1e3
positive = st.floats(1e-6, 1e3, allow_nan=False, allow_infinity=False)
fraction = st.floats(1e-3, 0.999)
vec3 = st.tuples(finite, finite, finite)
name = st.text("abcdefghijklmnopqrstuvwxyz_", min_size=1, max_size=8)


def selectors(depth: int = 2):
    leaf = st.one_of(
        st.just("all"),
        st.just(R.Border()),
        st.builds(R.Indices, st.lists(st.integers(0, 500), min_size=1, max_size=5).map(tuple)),
        st.builds(R.HalfSpace, vec3, vec3),
        st.builds(R.Ball, vec3, positive),
        st.builds(R.Box, vec3, vec3),
        st.builds(R.Wedge, st.floats(-360, 360), st.floats(-360, 360), vec3),
        st.builds(R.Nearest, st.lists(vec3, min_size=1, max_size=3).map(tuple)),
        st.builds(R.Patch, vec3, positive),
    )
    if depth == 0:
        return leaf
    inner = selectors(depth - 1)
    return st.one_of(
        leaf,
        st.builds(R.Union_, st.lists(inner, min_size=1, max_size=3).map(tuple)),
        st.builds(R.Intersection, st.lists(inner, min_size=1, max_size=3).map(tuple)),
        st.builds(R.Difference, inner, inner),
    )


def tables(ncomp: int):
    def build(times, values, periodic):
        return Table(tuple(times), tuple(values[: len(times)]), periodic)

    value = finite if ncomp == 1 else vec3
    times = st.lists(st.floats(0, 100), min_size=2, max_size=5, unique=True).map(sorted)
    return st.builds(build, times, st.lists(value, min_size=5, max_size=5), st.booleans())


scalar_schedule = st.one_of(
    st.builds(Constant, finite), tables(1), st.builds(Breathing, positive, fraction, finite, st.floats(0, 10))
)
vector_schedule = st.one_of(st.builds(Constant, vec3), tables(3))

forces = st.one_of(
    st.builds(Gravity, vec3),
    st.builds(ShapeMemory, positive, selectors()),
    st.builds(Damping, coef_n_s_per_m=st.floats(0, 1e3), region=selectors()),
    st.builds(Damping, critical_fraction=st.floats(0, 2), region=selectors()),
    st.builds(MassSpring, positive, selectors()),
    st.builds(Muscle, selectors(), scalar_schedule, axis=vec3, max_angle_deg=st.floats(1, 89)),
    st.builds(Muscle, selectors(), scalar_schedule, toward_m=vec3),
    st.builds(AppliedForce, selectors(), vector_schedule),
    st.builds(Attraction, selectors(), positive, vector_schedule, st.one_of(st.none(), vec3)),
    st.builds(SoftVolume, positive),
    st.builds(SoftVolume, bulk_modulus_pa=positive),
    st.builds(Damping, drag_n_s_per_m3=st.floats(0, 1e3), region=selectors()),
    st.builds(Pressure, scalar_schedule),
    st.builds(MuscleFibres, selectors(), scalar_schedule, axis=vec3),
    st.builds(MuscleFibres, selectors(), scalar_schedule, toward_m=vec3),
)
constraints = st.one_of(
    st.builds(Nailed, selectors()),
    st.just(Volume()),
    st.builds(Prescribed, selectors(), vector_schedule),
    st.builds(KeepIn, selectors(), st.just("half_space"), point_m=vec3, normal=vec3),
    st.builds(KeepIn, selectors(), st.just("ball"), center_m=vec3, radius_m=positive),
    st.builds(KeepIn, selectors(), st.just("box"), lo_m=vec3, hi_m=vec3),
)
meshes = st.one_of(
    st.builds(
        MeshSpec,
        st.just("uv_sphere"),
        radius_m=positive,
        segments=st.integers(3, 40),
        rings=st.integers(2, 30),
        center_m=vec3,
    ),
    st.builds(MeshSpec, st.just("icosphere"), radius_m=positive, subdivisions=st.integers(0, 7), center_m=vec3),
    st.builds(MeshSpec, generator=st.none(), path=st.just("body.stl"), unit_scale=positive),
)


@st.composite
def scenes(draw):
    fs = draw(st.lists(forces, max_size=4))
    cs = draw(st.lists(constraints, max_size=3))
    # a scene keeps at most one volume constraint (two are refused: issue 31)
    cs = [c for i, c in enumerate(cs) if not isinstance(c, Volume) or not any(isinstance(d, Volume) for d in cs[:i])]
    names = draw(st.lists(name, min_size=len(fs) + len(cs) + 2, max_size=len(fs) + len(cs) + 2, unique=True))
    fs = tuple(f.__class__(**{**f.__dict__, "name": n}) for f, n in zip(fs, names))
    cs = tuple(c.__class__(**{**c.__dict__, "name": n}) for c, n in zip(cs, names[len(fs) :]))
    rigid = draw(
        st.one_of(
            st.none(),
            st.builds(
                Rigid, st.just("trunk"), st.just((RigidLink("all", "rib_left", names[-1]),)), name, st.booleans()
            ),
        )
    )
    return Scene(
        formulation=draw(st.sampled_from(["paper", "continuum"])),
        mesh=draw(meshes),
        masses=draw(st.builds(Masses, total_kg=positive)),
        regions=draw(st.dictionaries(name, selectors(1), max_size=3)),
        forces=fs,
        constraints=cs,
        rigid=rigid,
        dt_s=draw(positive),
        integrator=draw(st.sampled_from(["explicit_euler", "symplectic_euler"])),
        duration_s=draw(positive),
        max_speed_m_s=draw(positive),
        name=draw(name),
    )


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(scenes())
def test_a_scene_survives_its_scene_file(scene):
    text = sf.scene_to_toml(scene)
    back = sf.scene_from_dict(tomllib.loads(text), source="roundtrip.toml")
    assert back == scene
    assert sf.scene_to_toml(back) == text


_SCALARS = st.one_of(
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=False, width=64),
    st.booleans(),
    st.text(max_size=12),  # quotes, brackets, braces, escapes: left an item a line where not plain
)
_VALUES = st.recursive(st.lists(_SCALARS, max_size=60), lambda inner: st.lists(inner, max_size=8), max_leaves=200)


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.text("abcdefgh_", min_size=1, max_size=8), _VALUES, max_size=5))
def test_compacted_arrays_hold_the_same_values(table):
    """The scene file's arrays written a line at a time (`compact_arrays`): the same TOML values
    as tomli_w's item per line, and no line longer than LINE but one that holds a single item."""
    import tomli_w

    from hybrid.scenefile.write import LINE, compact_arrays

    text = tomli_w.dumps(table)
    compact = compact_arrays(text)
    assert tomllib.loads(compact) == tomllib.loads(text)
    for line in compact.split("\n"):  # longer only where one item is
        assert len(line) <= LINE or tomllib.loads("x = " + line.strip().rstrip(","))["x"] is not None, line


def test_a_long_list_of_indices_takes_a_line_per_few_dozen():
    import tomli_w

    from hybrid.scenefile.write import compact_arrays

    text = tomli_w.dumps({"indices": list(range(1000)), "p": [[0.5, 1.0, -2.0]] * 3})
    compact = compact_arrays(text)
    assert len(text.splitlines()) > 1000 and len(compact.splitlines()) < 60
    assert "p = [[0.5, 1.0, -2.0], [0.5, 1.0, -2.0], [0.5, 1.0, -2.0]]" in compact
