"""The Mesh (hybrid.mesh.surface): immutable and pickled whole, loaded from files with the
path in every error, its geometry methods checking their input."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from helpers import dented_sphere, hemisphere, sphere_arrays

from hybrid.errors import MeshError
from hybrid.mesh import Mesh, uv_sphere


def test_geometry_methods_check_the_shape():
    m = uv_sphere()
    with pytest.raises(MeshError, match=r"\(80, 3\).*\(79, 3\)"):
        m.volume(m.vert_pos[:-1])


def test_require_closed():
    uv_sphere().require_closed("a volume constraint needs a closed surface")
    m = hemisphere()
    with pytest.raises(
        MeshError,
        match=r"a volume constraint needs a closed surface.*"
        r"open: 13 border edges.*\(\d+, \d+\)",
    ):
        m.require_closed("a volume constraint needs a closed surface")


def test_mesh_is_frozen_and_owns_its_arrays():
    pos, face = sphere_arrays()
    m = Mesh.from_arrays(pos, face, name="s")
    pos[0] = 99.0  # the caller's arrays stay theirs
    assert m.vert_pos[0, 2] == 1.0 and pos.flags.writeable
    for arr in (m.vert_pos, m.face_vert, m.ring_ptr, m.ring_vert, m.ring_closed, m.edge_vert, m.border_vert):
        assert not arr.flags.writeable
        with pytest.raises(ValueError):
            arr[0] = 0
    assert m.vert_pos.dtype == np.float64 and m.vert_pos.flags.c_contiguous
    assert m.face_vert.dtype == np.int32 and m.ring_ptr.dtype == np.int32
    assert m.ring_vert.dtype == np.int32 and m.ring_closed.dtype == bool
    with pytest.raises(AttributeError):
        m.name = "other"
    with pytest.raises(AttributeError):
        m.closed = False


def test_pickle_round_trip():
    m = dented_sphere()
    copy = pickle.loads(pickle.dumps(m))
    assert copy.name == m.name
    np.testing.assert_array_equal(copy.vert_pos, m.vert_pos)
    np.testing.assert_array_equal(copy.ring_vert, m.ring_vert)
    assert not copy.vert_pos.flags.writeable


@pytest.mark.parametrize("ext", ["stl", "obj", "ply", "off"])
def test_load_round_trip(tmp_path, ext):
    m = uv_sphere(radius=0.12)
    path = tmp_path / f"sphere.{ext}"
    m.to_trimesh().export(path)
    loaded = Mesh.load(path)
    assert loaded.name == "sphere"
    assert (loaded.nvert, loaded.nface) == (80, 156)  # STL's 468 corners merged back to 80
    assert loaded.closed
    # trimesh writes STL and binary PLY in float32 and OBJ with 8 digits.
    assert loaded.volume() == pytest.approx(m.volume(), rel=1e-6)
    np.testing.assert_allclose(loaded.vert_pos, m.vert_pos, atol=1e-7)
    np.testing.assert_array_equal(loaded.face_vert, m.face_vert)


def test_load_names_the_path(tmp_path):
    missing = tmp_path / "nowhere.stl"
    with pytest.raises(MeshError, match="nowhere.stl"):
        Mesh.load(missing)
    with pytest.raises(MeshError, match=r"sphere.xyz.*\.stl, \.obj, \.ply, \.off"):
        Mesh.load(tmp_path / "sphere.xyz")
    garbage = tmp_path / "garbage.off"
    garbage.write_text("this is not a mesh\n")
    with pytest.raises(MeshError, match="garbage.off"):
        Mesh.load(garbage)


def test_load_reports_validation_errors_with_the_path(tmp_path):
    m = uv_sphere()
    flipped = Mesh.to_trimesh(m)
    flipped.faces = flipped.faces[:, ::-1]
    path = tmp_path / "inside_out.ply"
    flipped.export(path)
    with pytest.raises(MeshError, match="inside_out.ply.*inward-facing"):
        Mesh.load(path, name="x")
