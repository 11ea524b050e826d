"""The trace's series measured from a run's frames (docs/metrics.md defines each):
what parts of the scene they need (`scene_parts`), and `TraceMetrics`, which takes the
scene's rest figures once and writes each batch of frames' rows."""

from __future__ import annotations

import numpy as np

from ..model import Model
from ..readouts import pitch_deg, quat_rot, swept_volumes
from ..scene import Muscle, MuscleFibres, SoftVolume, Volume
from ..schedule import Breathing, schedule_eval, stack_schedules
from ..step import F_ALVEOLAR, F_FLOW, F_KE, F_LUNG_VOLUME, F_PLEURAL, F_PRESSURE, F_TIME, F_VOLUME
from ..terms import Lungs
from ..terms.lungs import CMH2O_PA, CMH2O_PER_L, P_E, P_RECOIL, P_V0
from ..terms.volume import face_volume
from .trace import COLUMN, TRACE_KEYS

__all__ = ["SWEPT_REGION", "scene_parts", "apex_vertex", "thorax_body", "first_muscle", "muscle_label", "TraceMetrics"]


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
    """The integrated point highest (most cranial) at rest: the diaphragm's apex."""
    z = model.mesh.vert_pos[:, 2].copy()
    z[model.arrays.vert_free == 0] = -np.inf
    return int(np.argmax(z))


def _mean_z(pos: np.ndarray, vert: np.ndarray) -> np.ndarray:
    """Mean z of the points vert in each frame of pos (nframe, nvert, 3), summed in
    vert's order (a cumulative sum adds one point after the other): the same figure
    whatever the number of frames."""
    return np.cumsum(pos[:, vert, 2], axis=1)[:, -1] / len(vert)


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


#: the region whose swept volume the trace gives (`swept_volume_ml`)
SWEPT_REGION = "diaphragm"


class TraceMetrics:
    """The trace's rows of a run's frames: the scene's rest figures, taken once, and
    each series measured from the frames captured (`fill`)."""

    def __init__(self, model: Model):
        self.model = model
        self.parts = scene_parts(model)
        self.apex = apex_vertex(model)
        self.link = model.link_vert
        self.rest = model.mesh.vert_pos
        self.apex_z0 = self.rest[self.apex, 2]
        self.rib_z0 = self.rest[self.link, 2].mean() if self.link.size else 0.0
        # the rest volume: the volume terms' own, else the closed surface's (nothing for an open one)
        self.v0 = model.arrays.vol0 or (
            float(face_volume(model.arrays.face_vert, self.rest)) if model.mesh.closed else 0.0
        )
        muscle_sched, self.breath = first_muscle(model)
        # the muscle stiffness at each frame: its table stacked once, evaluated compiled
        self.muscle_table, self.muscle_fns = stack_schedules([muscle_sched]) if muscle_sched is not None else (None, [])
        self.muscle_val = np.zeros(3)
        self.swept_faces = model.mesh.face_vert[model.region_faces(SWEPT_REGION)] if "diaphragm" in self.parts else None
        self.thorax = thorax_body(model)
        self.thorax_axis = None  # the thorax's anterior axis in its own frame, from its pose at the first frame
        self.lung_par = model.arrays.lung_par

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
        abdominal = scal[:, F_PRESSURE] if "pressure" in self.parts else 0.0
        rows[:, COLUMN["transdiaphragmatic_pressure_change_cmh2o"]] = (
            abdominal - (pleural + lung_par[P_RECOIL])
        ) / CMH2O_PA

    def fill(self, rows, frames) -> None:
        """The trace's rows (`frames.count` of them) of the frames captured (`hybrid.loop.Frames`)."""
        k = frames.count
        parts = self.parts
        pos, scal = frames.pos[:k], frames.scal[:k]
        rows[:, COLUMN["t_s"]] = scal[:, F_TIME]
        rows[:, COLUMN["apex_descent_mm"]] = (self.apex_z0 - pos[:, self.apex, 2]) * 1e3
        rows[:, COLUMN["rib_lift_mm"]] = (_mean_z(pos, self.link) - self.rib_z0) * 1e3 if "ribs" in parts else np.nan
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
        if "muscle" in parts:
            for j, t in enumerate(scal[:, F_TIME].tolist()):
                rows[j, COLUMN["muscle_n_per_m"]] = self.muscle_at(t)
        else:
            rows[:, COLUMN["muscle_n_per_m"]] = np.nan
