"""The trace's series measured from a run's frames (docs/metrics.md defines each):
what parts of the scene they need (`scene_parts`), and `TraceMetrics`, which takes the
scene's rest figures once and writes each batch of frames' rows."""

from __future__ import annotations

import numpy as np

from ..mesh.geometry import vertex_area
from ..model import Model
from ..readouts import axis_crossing_z, pitch_deg, quat_rot, ring_faces, swept_volumes
from ..scene import Muscle, MuscleFibres, SoftVolume, Volume
from ..schedule import Breathing, schedule_eval, stack_schedules
from ..step import F_AIRWAY, F_ALVEOLAR, F_FLOW, F_KE, F_LUNG_VOLUME, F_PLEURAL, F_PRESSURE, F_TIME, F_VOLUME
from ..step_work import ControlArrays
from ..terms import Lungs
from ..terms.lungs import CMH2O_PA, CMH2O_PER_L, P_E, P_RECOIL, P_V0
from ..terms.volume import face_volume
from .trace import COLUMN, TRACE_KEYS

__all__ = [
    "SWEPT_REGION",
    "scene_parts",
    "apex_vertex",
    "lung_part_faces",
    "thorax_body",
    "first_muscle",
    "muscle_label",
    "TraceMetrics",
]


def scene_parts(model: Model) -> frozenset:
    """What the scene has that some metrics need: "ribs" (points linked to rigid
    bodies), "closed surface", "volume constraint" (the exact one), "pressure" (a
    volume term, exact or soft), "muscle", "diaphragm" (a region of that name) and "lungs"."""
    on = model.arrays.term_on
    parts = {
        "ribs": model.link_vert.size > 0,
        "closed surface": model.mesh.closed,
        "volume constraint": bool(on[Volume.id]),
        "pressure": bool(on[Volume.id] or on[SoftVolume.id]),
        "muscle": first_muscle(model)[0] is not None,
        "diaphragm": SWEPT_REGION in model.regions,
        "lungs": bool(on[Lungs.id]),
    }
    return frozenset(name for name, has in parts.items() if has)


def thorax_body(model: Model):
    """(body index among the frames' bodies, anterior, cranial: unit vectors of the scene's
    frame) of the thoracic body the scene's ribs hang on (`rigid.ribs.body`), or None."""
    rigid = model.rigid
    ribs = getattr(rigid, "ribs", None) if rigid is not None else None
    if rigid is None or ribs is None:
        return None
    b = int(rigid.model.body(ribs.body).id)
    return b - 1, ribs.anterior, ribs.cranial


def apex_vertex(model: Model) -> int:
    """The integrated point highest (most cranial) at rest: the diaphragm's apex. On a mesh
    refined from a file's (`mesh.level`), the highest of the file's points, which keep their
    indices and places at every level: the apex's vertical is then one line at every level (a
    new point beside it may stand a little higher: on the fitted trunk at level 2 one 0.017 mm
    higher moved the line 2.9 mm, and the dome's descent measured there with it)."""
    z = model.mesh.vert_pos[:, 2].copy()
    z[model.arrays.vert_free == 0] = -np.inf
    refinement = model.mesh.refinement
    if refinement is not None:
        z[len(refinement.coarse_pos) :] = -np.inf
    return int(np.argmax(z))


#: the edge rings about the apex whose faces the dome's axis crossing is sought in first
APEX_RINGS = 3


def _weighted_z(pos: np.ndarray, vert: np.ndarray, area: np.ndarray) -> np.ndarray:
    """The area-weighted mean z of the points vert (weights `area`, their shares of the
    surface at rest) in each frame of pos (nframe, nvert, 3): the mean height of the
    region, whatever its mesh. Summed in vert's order (a cumulative sum adds one point
    after the other): the same figure whatever the number of frames."""
    return np.cumsum(pos[:, vert, 2] * area, axis=1)[:, -1] / np.cumsum(area)[-1]


def lung_part_faces(model: Model) -> tuple:
    """The faces whose swept volumes are the lung volume change's parts: the cavity's floor
    (the membrane's faces under the lungs, in the membrane's orientation), then the membrane's
    other faces, the abdomen's boundary off the floor, split into the abdominal rib cage (every
    corner linked to a rigid body, or sliding on one: the zone of apposition the ribs hold) and
    the abdomen (the rest; nailed faces sweep nothing)."""
    n = model.nvert
    lung_face = model.arrays.lung_face
    floor = np.ascontiguousarray(lung_face[(lung_face < n).all(axis=1)][:, ::-1])
    under = {tuple(sorted(f)) for f in floor.tolist()}
    face = model.mesh.face_vert
    off = face[[tuple(sorted(f)) not in under for f in face.tolist()]]
    linked = np.zeros(n, bool)
    linked[model.link_vert] = True
    linked[model.slide_vert] = True
    held = linked[off].all(axis=1)
    return floor, off[held], off[~held]


def apex_height(metrics, pos: np.ndarray) -> np.ndarray:
    """The surface's height (m) on the vertical through the apex at rest, per frame of pos;
    the apex point's own height in a frame where the surface misses that line."""
    z = axis_crossing_z(metrics.apex_faces, pos, metrics.apex_xy)
    miss = np.isnan(z)
    if miss.any():
        z[miss] = axis_crossing_z(metrics.model.mesh.face_vert, pos[miss], metrics.apex_xy)
        miss = np.isnan(z)
        z[miss] = pos[miss, metrics.apex, 2]
    return z


def muscle_label(model: Model) -> str | None:
    """What `muscle_n_per_m` is for this scene's first muscle term, with its unit (the
    figure's label), or None without a muscle."""
    for term in model.scene.forces:
        if isinstance(term, Muscle):
            return "muscle stiffness (N/m)"
        if isinstance(term, MuscleFibres):
            return "muscle fibre tension (N/m)"
    return None


def first_muscle(model: Model):
    """The first muscle's schedule (a per-point muscle's stiffness, or a fibre
    tension), and its breathing waveform if it has one."""
    for term in model.scene.forces:
        if isinstance(term, (Muscle, MuscleFibres)):
            sched = term.stiffness if isinstance(term, Muscle) else term.tension_n_per_m
            return sched, (sched if isinstance(sched, Breathing) else None)
    return None, None


def first_muscle_key(model: Model) -> str | None:
    """The first muscle's input key ("forces['NAME'].tension_n_per_m" or ".stiffness"), or None."""
    for term in model.scene.forces:
        if isinstance(term, (Muscle, MuscleFibres)):
            return f"forces[{term.name!r}].{'stiffness' if isinstance(term, Muscle) else 'tension_n_per_m'}"
    return None


#: the region whose swept volume the trace gives (`swept_volume_ml`)
SWEPT_REGION = "diaphragm"


class TraceMetrics:
    """The trace's rows of a run's frames: the scene's rest figures, taken once, and
    each series measured from the frames captured (`fill`)."""

    def __init__(self, model: Model, control: ControlArrays | None = None):
        """`control`: the run's inputs, where a user's program may set the muscle's."""
        self.model = model
        self.parts = scene_parts(model)
        self.apex = apex_vertex(model)
        self.link = model.link_vert
        self.rest = model.mesh.vert_pos
        face = model.mesh.face_vert
        # the dome's height where the surface crosses the vertical through the apex at rest; the
        # faces within APEX_RINGS rings of it first (all of them in a frame where those miss)
        self.apex_xy = self.rest[self.apex, :2].copy()
        self.apex_faces = face[ring_faces(face, self.apex, APEX_RINGS)]
        self.apex_z0 = self.rest[self.apex, 2]
        # each point's share of the surface at rest: means over a region that are its integrals
        self.area = vertex_area(self.rest, face)
        self.link_area = self.area[self.link]
        self.rib_z0 = _weighted_z(self.rest[None], self.link, self.link_area)[0] if self.link.size else 0.0
        # the rest volume: the volume terms' own, else the closed surface's (nothing for an open one)
        self.v0 = model.arrays.vol0 or (
            float(face_volume(model.arrays.face_vert, self.rest)) if model.mesh.closed else 0.0
        )
        muscle_sched, self.breath = first_muscle(model)
        # the muscle stiffness at each frame: its table stacked once, evaluated compiled
        self.muscle_table, self.muscle_fns = stack_schedules([muscle_sched]) if muscle_sched is not None else (None, [])
        self.muscle_val = np.zeros(3)
        # the first muscle's row among the model's inputs: a value the user's program set
        # (`hybrid.Control`) is what ran, and what the trace records, not the schedule
        key = first_muscle_key(model)
        names = [k for k, _ in model.control_keys]
        self.muscle_row = names.index(key) if key in names else None
        self.control = control
        self.swept_faces = model.mesh.face_vert[model.region_faces(SWEPT_REGION)] if "diaphragm" in self.parts else None
        self.thorax = thorax_body(model)
        self.thorax_axis = None  # the thorax's anterior axis in its own frame, from its pose at the first frame
        self.lung_par = model.arrays.lung_par
        self.part_faces = lung_part_faces(model) if "lungs" in self.parts else None

    def rest_distance_mm(self, pos: np.ndarray) -> float:
        """The surface's root-mean-square distance from its rest shape (mm), each point weighted
        by its share of the surface: an integral over the body, which converges as the mesh is
        refined (a largest distance over points, at a stiffness jump, grows with refinement)."""
        d2 = ((pos - self.rest) ** 2).sum(axis=1)
        return float(np.sqrt((self.area * d2).sum() / self.area.sum()) * 1e3)

    def about(self) -> dict:
        """What the figure needs besides the series (`Trace.about`)."""
        about = {"muscle": muscle_label(self.model)}
        if "lungs" in self.parts:
            about["lung_elastance_cmh2o_per_l"] = float(self.lung_par[P_E]) / CMH2O_PER_L
            about["resting_recoil_cmh2o"] = float(self.lung_par[P_RECOIL]) / CMH2O_PA
        return about

    def muscle_at(self, t):
        if self.muscle_table is None:
            return 0.0
        if self.muscle_fns:
            return float(np.atleast_1d(self.muscle_fns[0][1](t))[0])
        schedule_eval(self.muscle_table, 0, t, self.muscle_val)
        return float(self.muscle_val[0])

    def lung_part_rows(self, rows, pos):
        """The lung volume change's parts (L): the abdomen's rib cage and wall off the floor by
        the volumes they swept outward, the pulmonary rib cage (the cavity's wall) as the lung
        change less what the floor swept into the abdomen (Mead & Loring's bookkeeping; the
        frames hold the membrane's points, not the wall's)."""
        floor, rib, wall = self.part_faces
        dome_in = -swept_volumes(floor, self.rest, pos) * 1e3
        rows[:, COLUMN["rib_cage_pulmonary_volume_change_l"]] = rows[:, COLUMN["lung_volume_change_l"]] - dome_in
        rows[:, COLUMN["rib_cage_abdominal_volume_change_l"]] = swept_volumes(rib, self.rest, pos) * 1e3
        rows[:, COLUMN["abdomen_volume_change_l"]] = swept_volumes(wall, self.rest, pos) * 1e3

    def lung_rows(self, rows, scal):
        """The lungs' series of the frames scal, NaN without lungs."""
        keys = [k for k in TRACE_KEYS[COLUMN["lung_volume_change_l"] :]]
        if "lungs" not in self.parts:
            for key in keys:
                rows[:, COLUMN[key]] = np.nan
            return
        lung_par = self.lung_par
        pleural = scal[:, F_PLEURAL]
        rows[:, COLUMN["lung_volume_change_l"]] = (scal[:, F_LUNG_VOLUME] - lung_par[P_V0]) * 1e3
        rows[:, COLUMN["flow_l_per_s"]] = scal[:, F_FLOW] * 1e3
        rows[:, COLUMN["pleural_pressure_cmh2o"]] = pleural / CMH2O_PA
        rows[:, COLUMN["alveolar_pressure_cmh2o"]] = scal[:, F_ALVEOLAR] / CMH2O_PA
        rows[:, COLUMN["airway_opening_pressure_cmh2o"]] = scal[:, F_AIRWAY] / CMH2O_PA
        abdominal = scal[:, F_PRESSURE] if "pressure" in self.parts else 0.0
        rows[:, COLUMN["gastric_pressure_cmh2o"]] = abdominal / CMH2O_PA
        rows[:, COLUMN["transdiaphragmatic_pressure_change_cmh2o"]] = (
            abdominal - (pleural + lung_par[P_RECOIL])
        ) / CMH2O_PA

    def fill(self, rows, frames) -> None:
        """The trace's rows (`frames.count` of them) of the frames captured (`hybrid.loop.Frames`)."""
        k = frames.count
        parts = self.parts
        pos, scal = frames.pos[:k], frames.scal[:k]
        rows[:, COLUMN["t_s"]] = scal[:, F_TIME]
        rows[:, COLUMN["apex_descent_mm"]] = (self.apex_z0 - apex_height(self, pos)) * 1e3
        rows[:, COLUMN["rib_lift_mm"]] = (
            (_weighted_z(pos, self.link, self.link_area) - self.rib_z0) * 1e3 if "ribs" in parts else np.nan
        )
        vol = scal[:, F_VOLUME]
        closed = "closed surface" in parts
        rows[:, COLUMN["volume_m3"]] = vol if closed else np.nan
        rows[:, COLUMN["volume_rel_change"]] = np.abs(vol - self.v0) / self.v0 if closed else np.nan
        rows[:, COLUMN["volume_rel_error"]] = (
            rows[:, COLUMN["volume_rel_change"]] if "volume constraint" in parts else np.nan
        )
        rows[:, COLUMN["pressure_pa"]] = scal[:, F_PRESSURE] if "pressure" in parts else np.nan
        rows[:, COLUMN["kinetic_energy_j"]] = scal[:, F_KE]
        rows[:, COLUMN["swept_volume_ml"]] = (
            -swept_volumes(self.swept_faces, self.rest, pos) * 1e6 if self.swept_faces is not None else np.nan
        )
        if self.thorax is not None:
            bq = frames.body_quat[:k, self.thorax[0]]
            if self.thorax_axis is None:
                self.thorax_axis = quat_rot(bq[:1])[0].T @ self.thorax[1]
            rows[:, COLUMN["thorax_pitch_deg"]] = pitch_deg(bq, self.thorax_axis, self.thorax[1], self.thorax[2])
        else:
            rows[:, COLUMN["thorax_pitch_deg"]] = np.nan
        self.lung_rows(rows, scal)
        if self.part_faces is not None:
            self.lung_part_rows(rows, pos)
        c, row = self.control, self.muscle_row
        if "muscle" in parts and c is not None and row is not None and c.user[row]:
            # set by the user's program: held over the compiled call whose frames these are
            rows[:, COLUMN["muscle_n_per_m"]] = c.value[row, 0]
        elif "muscle" in parts:
            for j, t in enumerate(scal[:, F_TIME].tolist()):
                rows[j, COLUMN["muscle_n_per_m"]] = self.muscle_at(t)
        else:
            rows[:, COLUMN["muscle_n_per_m"]] = np.nan
