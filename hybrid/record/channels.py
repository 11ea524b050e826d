"""The recording's channels: what the writer takes of the model, the file's head
(metadata, schemas, channels, the geoms' scene) and each channel's encoder program;
batches of frames encoded into chunks."""

from __future__ import annotations

import json
import zlib

import numpy as np

from ..loads import topics as load_topics
from ..observers.metrics import muscle_label
from ..scene import body_axes
from .encoder import (
    MAX_DEPTH,
    OP_BEGIN,
    OP_CLOUD,
    OP_CONST,
    OP_DOUBLE,
    OP_END,
    OP_IF_FINITE,
    OP_POINTS,
    OP_STAMP,
    POINT3_BYTES,
    RECORD_HEAD,
    _load_encoder,
    _tag,
    encode_frames,
)
from .mcap_writer import _McapWriter
from .schemas import (
    GEOM_BOX,
    GEOM_CAPSULE,
    GEOM_CYLINDER,
    GEOM_ELLIPSOID,
    GEOM_SPHERE,
    SCALAR_CHANNELS,
    _schemas,
    body_geoms,
    region_colours,
)


def _plan(sim, every_s: float) -> dict:
    """What the writer needs to know of the model, as plain data."""
    model = sim.model
    names, label, colours = region_colours(model)
    mj_model = sim.mj_model
    bodies = (
        [(b, mj_model.body(b).name or f"body{b}") for b in range(1, mj_model.nbody)] if mj_model is not None else []
    )
    return {
        "scene": model.scene.name,
        "dt_s": model.dt_s,
        "every_s": every_s,
        "nvert": model.mesh.nvert,
        "face_vert": np.asarray(model.mesh.face_vert, np.int64),
        "regions": names,
        "vert_label": label,
        "colours": colours,
        "link_vert": np.asarray(model.link_vert),
        "rest": np.array(model.mesh.vert_pos, float),
        "geoms": body_geoms(mj_model) if mj_model is not None else [],
        "bodies": bodies,
        "loads": [],
        "axes": body_axes(model.scene),
        "muscle": muscle_label(model),
    }


def _nslot(nbody: int, nload: int = 0) -> int:
    """Number slots of a frame: t, the scalars, each body's x, y, z and w, x, y, z, then
    each load channel's x, y, z (`hybrid.loads`)."""
    return 1 + len(SCALAR_CHANNELS) + 7 * nbody + 3 * nload


def _load_slot(nbody: int) -> int:
    """The first load slot of a frame (`_nslot`)."""
    return 1 + len(SCALAR_CHANNELS) + 7 * nbody


def _frame_bytes_estimate(plan: dict, mesh_every: int) -> int:
    """About the bytes of a frame's messages (to size a chunk's batch of frames)."""
    n, nface, nbody = plan["nvert"], len(plan["face_vert"]), len(plan["bodies"])
    mesh = 30 * n + 38 * n + 12 * nface + 200
    cloud = 16 * n + 200 if mesh_every > 1 else 0
    return mesh // mesh_every + cloud + 130 * nbody + 50 * (len(SCALAR_CHANNELS) + 3 * len(plan["loads"])) + 100


def _geom_scene(geoms: list[dict]) -> bytes:
    """A foxglove.SceneUpdate with one frame-locked entity per body holding its geoms."""
    from foxglove_schemas_protobuf.Color_pb2 import Color
    from foxglove_schemas_protobuf.Pose_pb2 import Pose
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from foxglove_schemas_protobuf.Vector3_pb2 import Vector3

    scene = SceneUpdate()
    by_body: dict[str, object] = {}
    for g in geoms:
        if g["body_id"] == 0:
            continue  # world geoms (floors) are not drawn
        e = by_body.get(g["body"])
        if e is None:
            e = by_body[g["body"]] = scene.entities.add(frame_id=g["body"], id="geoms_" + g["body"], frame_locked=True)
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = g["pos"]
        q = pose.orientation
        q.w, q.x, q.y, q.z = g["quat"]
        colour = Color(r=g["rgba"][0], g=g["rgba"][1], b=g["rgba"][2], a=g["rgba"][3])
        s = g["size"]
        if g["type"] in (GEOM_CAPSULE, GEOM_CYLINDER):
            length = 2 * s[1] + (2 * s[0] if g["type"] == GEOM_CAPSULE else 0.0)
            e.cylinders.add(
                pose=pose, size=Vector3(x=2 * s[0], y=2 * s[0], z=length), bottom_scale=1.0, top_scale=1.0, color=colour
            )
        elif g["type"] == GEOM_SPHERE:
            e.spheres.add(pose=pose, size=Vector3(x=2 * s[0], y=2 * s[0], z=2 * s[0]), color=colour)
        elif g["type"] == GEOM_ELLIPSOID:
            e.spheres.add(pose=pose, size=Vector3(x=2 * s[0], y=2 * s[1], z=2 * s[2]), color=colour)
        elif g["type"] == GEOM_BOX:
            e.cubes.add(pose=pose, size=Vector3(x=2 * s[0], y=2 * s[1], z=2 * s[2]), color=colour)
    return scene.SerializeToString()


class _FrameWriter:
    """Writes the file's head (metadata, schemas, channels, geoms) and then batches of
    frames, each batch encoded by one compiled pass into one chunk."""

    def __init__(self, file, plan: dict, *, mesh_every: int, chunk_size: int):
        from foxglove_schemas_protobuf.Color_pb2 import Color
        from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
        from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
        from foxglove_schemas_protobuf.Pose_pb2 import Pose
        from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
        from foxglove_schemas_protobuf.TriangleListPrimitive_pb2 import TriangleListPrimitive

        self._file = file
        self._writer = w = _McapWriter(file, chunk_size=chunk_size)
        n, face, colours = plan["nvert"], plan["face_vert"], plan["colours"]
        bodies = [name for _, name in plan["bodies"]]
        description = json.dumps(
            {
                "scene": plan["scene"],
                "dt_s": plan["dt_s"],
                "every_s": plan["every_s"],
                "nvert": n,
                "face_vert": face.tolist(),
                "regions": plan["regions"],
                "vert_label": plan["vert_label"].tolist(),
                "vert_rgba": np.round(colours, 4).tolist(),
                "link_vert": plan["link_vert"].tolist(),
                "geoms": plan["geoms"],
                # the body's anterior and cranial directions (`hybrid.scene.body_axes`), for the pictures
                "anterior": list(plan["axes"][0]),
                "cranial": list(plan["axes"][1]),
                "bodies": bodies,
                "loads": plan["loads"],
                # what /muscle holds, with its unit ("muscle fibre tension (N/m)"), or None
                "muscle": plan["muscle"],
                "provenance": plan.get("provenance"),
            }
        )
        # MCAP gives metadata no CRC of its own: the reader checks this one
        w.metadata(
            "hybrid", {"description": description, "description_crc32": f"{zlib.crc32(description.encode()):08x}"}
        )
        schemas = {name: w.schema(name, "protobuf", data) for name, data in _schemas().items()}

        def channel(topic, schema):
            return w.channel(topic, "protobuf", schemas[schema])

        const = bytearray()
        prog: list[tuple[int, int, int]] = []
        programs: list[tuple[int, int, int, int]] = []  # (channel, first op, end op, every)

        def fields(message) -> None:
            """Fields encoded once by protobuf (concatenated fields are a valid message)."""
            a = len(const)
            const.extend(message.SerializeToString())
            prog.append((OP_CONST, a, len(const)))

        def program(ch: int, every: int, ops) -> None:
            p0 = len(prog)
            for op in ops:
                fields(op) if hasattr(op, "SerializeToString") else prog.append(op)
            depth = np.cumsum([(op == OP_BEGIN) - (op == OP_END) for op, _, _ in prog[p0:]])
            # the encoder sizes nested messages on a stack of MAX_DEPTH, unchecked
            assert depth[-1] == 0 and depth.min() >= 0 and depth.max() < MAX_DEPTH, "unbalanced program"
            programs.append((ch, p0, len(prog), every))

        def begin(field):
            return (OP_BEGIN, _tag(field, 2), 0)

        def stamp(field):
            return (OP_STAMP, _tag(field, 2), 0)

        def double(field, slot):
            return (OP_DOUBLE, _tag(field, 1), slot)

        end = (OP_END, 0, 0)
        identity = Pose()
        identity.orientation.w = 1.0
        # small meshes: the triangle list every frame; large ones: the point cloud every
        # frame (x, y, z float32, r, g, b, a uint8: 16 bytes a point), the triangles less often
        self.has_cloud = mesh_every > 1
        self._cloud = np.zeros((0, n), dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
        self._rgba = np.round(colours * 255).astype(np.uint8)
        if self.has_cloud:
            T = PackedElementField
            cloud_fields = [
                PackedElementField(name=k, offset=o, type=T.FLOAT32) for k, o in (("x", 0), ("y", 4), ("z", 8))
            ]
            cloud_fields += [
                PackedElementField(name=k, offset=12 + i, type=T.UINT8)
                for i, k in enumerate(("red", "green", "blue", "alpha"))
            ]
            program(
                channel("/membrane/points", "foxglove.PointCloud"),
                1,
                [
                    stamp(1),
                    PointCloud(frame_id="world", pose=identity, point_stride=16, fields=cloud_fields),
                    (OP_CLOUD, _tag(6, 2), 0),
                ],
            )
        # triangle list (SceneUpdate.entities = 2, SceneEntity.triangles = 12): the
        # points change, indices and colours do not
        entity = SceneEntity(frame_id="world", id="membrane", frame_locked=False)
        entity.lifetime.SetInParent()
        tri = TriangleListPrimitive(
            pose=identity,
            color=Color(r=0.8, g=0.8, b=0.8, a=1.0),
            colors=[Color(r=r, g=g, b=b, a=a) for r, g, b, a in colours.tolist()],
            indices=face.ravel().tolist(),
        )
        program(
            channel("/membrane/mesh", "foxglove.SceneUpdate"),
            mesh_every,
            [begin(2), stamp(1), entity, begin(12), tri, (OP_POINTS, _tag(2, 2), 0), end, end],
        )
        for i, topic in enumerate(SCALAR_CHANNELS):
            program(channel(topic, "hybrid.Scalar"), 1, [(OP_IF_FINITE, 1 + i, 0), double(1, 0), double(2, 1 + i)])
        if bodies:
            ops: list = []
            for b, name in enumerate(bodies):  # FrameTransforms.transforms = 1
                s = 1 + len(SCALAR_CHANNELS) + 7 * b  # x, y, z, qw, qx, qy, qz
                ops += [
                    begin(1),
                    stamp(1),
                    FrameTransform(parent_frame_id="world", child_frame_id=name),
                    begin(4),
                    double(1, s),
                    double(2, s + 1),
                    double(3, s + 2),
                    end,
                    begin(5),
                    double(1, s + 4),
                    double(2, s + 5),
                    double(3, s + 6),
                    double(4, s + 3),
                    end,
                    end,
                ]
            program(channel("/rigid/transforms", "foxglove.FrameTransforms"), 1, ops)
            w.message(channel("/rigid/geoms", "foxglove.SceneUpdate"), 0, _geom_scene(plan["geoms"]))
            w.flush_chunk()
        first = _load_slot(len(bodies))
        for i, topic in enumerate(load_topics(plan["loads"])):  # each load's x, y, z (hybrid.loads)
            program(
                channel(topic, "hybrid.Scalar"), 1, [(OP_IF_FINITE, first + i, 0), double(1, 0), double(2, first + i)]
            )
        self._const = np.frombuffer(bytearray(const), np.uint8)  # writable: the type of the cloud's rows
        self._prog = np.array(prog, np.int64).reshape(-1, 3)
        self._programs = np.array(programs, np.int64)
        self._size = np.zeros(len(prog), np.int64)
        # bytes of a frame at most: a nested message's key and length 8 at most, a time stamp 20
        leaf = {OP_POINTS: n * (2 + 1 + POINT3_BYTES), OP_CLOUD: 16 * n + 12}
        self.frame_bytes = len(const) + len(programs) * RECORD_HEAD + sum(leaf.get(op, 20) for op, _, _ in prog)
        self._out = np.empty(0, np.uint8)
        self._index = np.empty((0, 3), np.int64)
        _load_encoder()

    def write(self, t_s, number, pos, frame0: int) -> None:
        """Frames frame0, frame0 + 1, ...: t_s (nframe,) s, number (nframe, nslot), pos
        (nframe, nvert, 3) m, as one chunk."""
        nframe = len(t_s)
        t_ns = np.maximum(np.round(np.asarray(t_s) * 1e9), 0).astype(np.int64)
        if len(self._cloud) < nframe:
            self._cloud = np.zeros((nframe, pos.shape[1]), self._cloud.dtype)
            self._cloud["rgba"] = self._rgba
        cloud = self._cloud[:nframe]
        if self.has_cloud:
            cloud["xyz"] = pos
        need = nframe * self.frame_bytes
        if len(self._out) < need:
            self._out = np.empty(2 * need, np.uint8)
        if len(self._index) < nframe * len(self._programs):
            self._index = np.empty((2 * nframe * len(self._programs), 3), np.int64)
        number = np.ascontiguousarray(number, "<f8")
        pos = np.ascontiguousarray(pos, "<f8")
        k, m = encode_frames(
            t_ns,
            number,
            cloud.view(np.uint8).reshape(nframe, -1),
            pos.reshape(nframe, -1),
            frame0,
            self._const,
            self._prog,
            self._programs,
            self._out,
            self._index,
            self._size,
        )
        self._writer.add_chunk(self._out[:k], self._index[:m])

    def close(self) -> None:
        try:
            self._writer.finish()
        finally:
            self._file.close()
