"""What a recording holds, as data: the topic table and its constants, the model's
description written with it (each point's region colour, each body's geoms), and
the protobuf schemas (foxglove's well-known ones and hybrid.Scalar) as MCAP schema
records, with the message classes built back from them."""

from __future__ import annotations

import functools

import numpy as np

#: the scalar channels, and the runner's trace key each one takes its value from
SCALAR_CHANNELS = {
    "/volume": "volume_m3",
    "/volume_rel_error": "volume_rel_error",
    "/pressure": "pressure_pa",
    "/rib_elevation": "rib_lift_mm",
    "/apex_descent": "apex_descent_mm",
    "/muscle": "muscle_n_per_m",  # a fibre tension or the paper's stiffness: the description's `muscle` says which
    "/kinetic_energy": "kinetic_energy_j",
    # scenes with lungs (no message otherwise): in the trace's units, L, L/s, cmH2O
    "/lungs/volume_change": "lung_volume_change_l",
    "/lungs/flow": "flow_l_per_s",
    "/lungs/pleural_pressure": "pleural_pressure_cmh2o",
    "/lungs/alveolar_pressure": "alveolar_pressure_cmh2o",
    "/lungs/airway_opening_pressure": "airway_opening_pressure_cmh2o",
    "/lungs/gastric_pressure": "gastric_pressure_cmh2o",
    "/lungs/transdiaphragmatic_pressure_change": "transdiaphragmatic_pressure_change_cmh2o",
    "/lungs/rib_cage_pulmonary_volume_change": "rib_cage_pulmonary_volume_change_l",
    "/lungs/rib_cage_abdominal_volume_change": "rib_cage_abdominal_volume_change_l",
    "/lungs/abdomen_volume_change": "abdomen_volume_change_l",
}

#: meshes with at most this many points get the triangle list every frame
MESH_EVERY_FRAME_MAX = 2000

# a qualitative palette (r, g, b) in 0..1, one colour per region in order
_PALETTE = [
    (0.84, 0.37, 0.30),
    (0.30, 0.52, 0.78),
    (0.45, 0.70, 0.35),
    (0.93, 0.66, 0.22),
    (0.58, 0.40, 0.74),
    (0.55, 0.34, 0.29),
    (0.89, 0.47, 0.76),
    (0.50, 0.50, 0.50),
    (0.74, 0.74, 0.13),
    (0.09, 0.75, 0.81),
]
_UNLABELLED = (0.80, 0.80, 0.80)


def region_colours(model) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Each point's region for display: the smallest region that holds it (the most
    specific: "dome" rather than "diaphragm", "spine" rather than "fixed").
    Returns (names, vert_label (nvert,) int, -1 where no region; colours (nvert, 4) rgba 0..1)."""
    n = model.mesh.nvert
    regions = {k: np.asarray(v, int) for k, v in model.regions.items() if 0 < len(v) < n}
    order = sorted(regions, key=lambda k: (-len(regions[k]), k))  # largest first: the smallest wins
    label = np.full(n, -1)
    for i, name in enumerate(order):
        label[regions[name]] = i
    present = sorted(set(label[label >= 0].tolist()))
    names = [order[i] for i in present]
    remap = np.full(len(order) + 1, -1)
    remap[present] = np.arange(len(present))
    label = remap[label]  # -1 stays -1 (remap[-1])
    table = np.array(_PALETTE + [_UNLABELLED])  # row -1: no region
    colours = np.ones((n, 4))
    colours[:, :3] = table[np.where(label >= 0, label % len(_PALETTE), -1)]
    return names, label, colours


SCALAR_PROTO = "hybrid/Scalar.proto"


def _scalar_file():
    """hybrid.Scalar {double t = 1 (simulated time, s); double value = 2;} as a
    protobuf file descriptor."""
    from google.protobuf import descriptor_pb2

    f = descriptor_pb2.FileDescriptorProto(name=SCALAR_PROTO, package="hybrid", syntax="proto3")
    msg = f.message_type.add(name="Scalar")
    for number, name in ((1, "t"), (2, "value")):
        msg.field.add(
            name=name,
            number=number,
            type=descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE,
            label=descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL,
            json_name=name,
        )
    return f


def _descriptor_set(file_descriptor) -> bytes:
    """A FileDescriptorSet of a .proto file and everything it imports (an MCAP
    protobuf schema)."""
    from google.protobuf import descriptor_pb2

    out = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(fd) -> None:
        for dep in fd.dependencies:
            if dep.name not in seen:
                seen.add(dep.name)
                add(dep)
        fd.CopyToProto(out.file.add())

    add(file_descriptor)
    return out.SerializeToString()


@functools.lru_cache(maxsize=1)
def _schemas() -> dict[str, bytes]:
    """The schemas written here, by name: foxglove's (from foxglove-schemas-protobuf) and hybrid.Scalar."""
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from google.protobuf import descriptor_pb2

    out = {
        m.DESCRIPTOR.full_name: _descriptor_set(m.DESCRIPTOR.file) for m in (SceneUpdate, FrameTransforms, PointCloud)
    }
    out["hybrid.Scalar"] = descriptor_pb2.FileDescriptorSet(file=[_scalar_file()]).SerializeToString()
    return out


def _message_classes(schemas: dict[str, bytes]) -> dict:
    """Message classes, by name, built from the schemas a file holds."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    pool = descriptor_pool.DescriptorPool()
    out = {}
    for name, data in schemas.items():
        fds = descriptor_pb2.FileDescriptorSet.FromString(data)
        for fd in fds.file:
            try:
                pool.Add(fd)
            except (TypeError, ValueError):
                pass  # already in the pool (shared imports)
        out[name] = message_factory.GetMessageClass(pool.FindMessageTypeByName(name))
    return out


# mjtGeom values (stable in MuJoCo's C API): plane 0, hfield 1, sphere 2, capsule 3,
# ellipsoid 4, cylinder 5, box 6, mesh 7
GEOM_SPHERE, GEOM_CAPSULE, GEOM_ELLIPSOID, GEOM_CYLINDER, GEOM_BOX = 2, 3, 4, 5, 6
GEOM_MESH = 7

#: how many of a model's mesh vertices (its bones' surfaces) the pictures draw, in all
MESH_POINTS = 8000
#: ... and at least this many of each mesh
MESH_POINTS_MIN = 50


def body_geoms(mj_model) -> list[dict]:
    """Each geom of a body (world geoms too) in its body's frame, for display, with its
    MuJoCo geom group (`hybrid.render.shown_geoms` hides groups 3 and above). A mesh geom (a
    bone's surface) carries "points": evenly strided vertices of its mesh in the geom's frame,
    `MESH_POINTS` over all the meshes in proportion to their vertices (the pictures draw the
    skeleton as these dots; 0.1 mm rounding)."""
    mesh = [g for g in range(mj_model.ngeom) if int(mj_model.geom_type[g]) == GEOM_MESH]
    total = sum(int(mj_model.mesh_vertnum[mj_model.geom_dataid[g]]) for g in mesh)
    out = []
    for g in range(mj_model.ngeom):
        body = int(mj_model.geom_bodyid[g])
        geom = {
            "body": mj_model.body(body).name or f"body{body}",
            "body_id": body,
            "type": int(mj_model.geom_type[g]),
            "size": mj_model.geom_size[g].tolist(),
            "pos": mj_model.geom_pos[g].tolist(),
            "quat": mj_model.geom_quat[g].tolist(),
            "rgba": mj_model.geom_rgba[g].tolist(),
            "name": mj_model.geom(g).name,
            "group": int(mj_model.geom_group[g]),
        }
        if g in mesh:
            m = int(mj_model.geom_dataid[g])
            start, n = int(mj_model.mesh_vertadr[m]), int(mj_model.mesh_vertnum[m])
            keep = min(n, max(MESH_POINTS_MIN, round(MESH_POINTS * n / total)))
            rows = start + np.linspace(0, n - 1, keep).round().astype(int)
            geom["points"] = np.round(mj_model.mesh_vert[rows], 4).tolist()
        out.append(geom)
    return out
