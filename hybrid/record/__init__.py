"""Record a run to MCAP, in Foxglove's well-known schemas (protobuf encoding), and read it back.

`hybrid run` writes `DIR/run.mcap` through a `Recorder`, an observer of the runner
(`hybrid.run.run(..., observers=[rec])`) called at each frame. Channels:

- `/membrane/mesh`     foxglove.SceneUpdate: the membrane as one TriangleListPrimitive
  with per-vertex region colours, its points as exact doubles; every frame for
  meshes up to `MESH_EVERY_FRAME_MAX` points, every `mesh_every` frames above;
- `/membrane/points`   foxglove.PointCloud, every frame, for the larger meshes only:
  the points as float32 x, y, z and their region colour (uint8 r, g, b, a);
- `/rigid/transforms`  foxglove.FrameTransforms: each MuJoCo body's pose (`xpos`,
  `xquat`) as the frame `world` -> body name (scenes with a rigid part);
- `/rigid/geoms`       foxglove.SceneUpdate, once: each body's geoms in its own frame
  (capsules and cylinders as cylinders, spheres, boxes), frame-locked;
- scalars, `hybrid.Scalar` {double t (s); double value}: `/volume` (m^3),
  `/volume_rel_error`, `/pressure` (Pa), `/rib_elevation` (mm), `/apex_descent` (mm),
  `/muscle` (N/m: a fibre tension or the paper's stiffness), `/kinetic_energy` (J), as far as the observer is given them.

Log times are the simulated time in nanoseconds (t = 0 at the start). Each schema is
a protobuf FileDescriptorSet (foxglove's from `foxglove-schemas-protobuf`). The model's
description (faces, region of each point, colours, geoms) is an MCAP metadata record
named "hybrid", so that `hybrid render` needs nothing but the file.

Cost: the run's thread only copies each block of frames (positions, body poses,
their scalars from the runner's trace). The frames go to a writer thread (at the end of
a block once half a chunk, about 0.5 MiB, is held) that writes the file's head with
the first ones, encodes every message of every
frame in one compiled pass (protobuf: numbers are copied as their 8 bytes, the
fields that do not change are encoded once), then compresses (zstd at a fast level)
and writes the chunk. The encoder and the compressor release the GIL, as do the
run's compiled steps, so the two go on side by side. `hybrid bench` times the
breathing run with and without the recording.

Crash safety: the frames held are handed to the writer at least every `flush_s`
seconds of wall time, each batch written as a whole chunk, so a killed process leaves
every frame but those of its last second or so; `close()` (called in a `finally` by `hybrid run`, or by
`with Recorder(...)`) encodes the rest and finishes the file on an error or an
interrupt. `read` accepts unfinished files (no summary, truncated last record),
with a warning.

Reading (`read`, `frames`) verifies every chunk it reads (CRC, header, message
indexes) and the file's structure; a corrupt chunk raises `RecordingError`, or is
skipped with a `RecordingWarning` under `strict=False`. A time window (`t_s`) and a
choice of topics read only the chunks that overlap the window.

The package, by concern (imports point down the list; reading takes only the schemas):
`schemas` (topics, constants, the model's description, protobuf schemas); `encoder`
(the compiled protobuf pass) and `mcap_writer` (the file's records); `channels` (the
file's head and each channel's program); `recorder` (the `Recorder` and its writer
thread); `mcap_reader` (the file's records read back and verified, chunk by chunk) and
`reader` (`read`, `frames`: the records decoded into arrays).
"""

from .reader import TOPICS, RecordingError, RecordingWarning, frames, read
from .recorder import Recorder, record_steps
from .schemas import (
    GEOM_BOX,
    GEOM_CAPSULE,
    GEOM_CYLINDER,
    GEOM_ELLIPSOID,
    GEOM_MESH,
    GEOM_SPHERE,
    MESH_EVERY_FRAME_MAX,
    MESH_POINTS,
    SCALAR_CHANNELS,
    body_geoms,
    region_colours,
)

__all__ = [
    "Recorder",
    "record_steps",
    "read",
    "frames",
    "RecordingError",
    "RecordingWarning",
    "TOPICS",
    "region_colours",
    "body_geoms",
    "SCALAR_CHANNELS",
    "MESH_EVERY_FRAME_MAX",
    "GEOM_SPHERE",
    "GEOM_CAPSULE",
    "GEOM_ELLIPSOID",
    "GEOM_CYLINDER",
    "GEOM_BOX",
    "GEOM_MESH",
    "MESH_POINTS",
]
