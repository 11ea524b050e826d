"""A run's summary (docs/outputs.md, docs/metrics.md): its status, steps and times, each
series' range over the run (`metric_table`), the top-level figures of earlier versions,
the work of breathing, and how the run was made."""

from __future__ import annotations

import numpy as np

from ..model import Model
from ..provenance import run_provenance
from ..respiratory import work_of_breathing
from .metrics import scene_parts
from .trace import COLUMN, TRACE_KEYS, Trace

__all__ = ["METRIC_KEYS", "metric_table", "headline", "breathing_work", "run_summary"]

#: the series a summary gives min, max and their times of (all but the time)
METRIC_KEYS = TRACE_KEYS[1:]


def metric_table(trace: Trace) -> dict:
    """{series: {"min", "max", "t_min_s", "t_max_s"}} for each series of `METRIC_KEYS`
    the scene has (a series of NaN, a part it lacks, is left out)."""
    table = {}
    for key in METRIC_KEYS:
        i = COLUMN[key]
        if np.isfinite(trace.highest[i]):
            table[key] = {
                "min": float(trace.lowest[i]),
                "max": float(trace.highest[i]),
                "t_min_s": float(trace.t_lowest[i]),
                "t_max_s": float(trace.t_highest[i]),
            }
    return table


def headline(trace: Trace) -> dict:
    """The summary's top-level metrics (kept for earlier scripts; docs/metrics.md):
    only those of the parts the scene has, but `volume_rel_error_max`, null without
    the exact volume constraint."""
    table = metric_table(trace)
    head = {"volume_rel_error_max": table["volume_rel_error"]["max"] if "volume_rel_error" in table else None}
    if "volume_rel_change" in table:
        head["volume_rel_change_max"] = table["volume_rel_change"]["max"]
    if "pressure_pa" in table:
        head["pressure_min_pa"], head["pressure_max_pa"] = table["pressure_pa"]["min"], table["pressure_pa"]["max"]
    if "rib_lift_mm" in table:
        head["rib_lift_mm"] = table["rib_lift_mm"]["max"]
    head["apex_descent_mm"] = table["apex_descent_mm"]["max"]
    if "thorax_pitch_deg" in table:
        pitch = table["thorax_pitch_deg"]
        head["thorax_pitch_change_deg_max"] = max(abs(pitch["min"]), abs(pitch["max"]))
    if "lung_volume_change_l" in table:  # the swing over the run: a run of steady breaths' tidal volume
        vol = table["lung_volume_change_l"]
        head["tidal_volume_l"] = vol["max"] - vol["min"]
        pdi = table["transdiaphragmatic_pressure_change_cmh2o"]
        head["transdiaphragmatic_pressure_swing_cmh2o"] = pdi["max"] - pdi["min"]
    return head


#: the lung volume change's parts and their summary keys (shares of it at the largest volume)
SHARES = {
    "rib_cage_pulmonary_volume_change_l": "pulmonary_rib_cage_share",
    "rib_cage_abdominal_volume_change_l": "abdominal_rib_cage_share",
    "abdomen_volume_change_l": "abdomen_share",
}


def breathing_work(trace: Trace, model: Model) -> dict:
    """The work of breathing's summary keys (`hybrid.respiratory.work_of_breathing`), from the
    trace's lung volume; and each part's share of the lung volume change at its largest
    (from rest; null when the lungs never filled above rest)."""
    cols = trace.columns(("t_s", "lung_volume_change_l", *SHARES))
    vol = cols["lung_volume_change_l"]
    k = int(np.argmax(vol)) if len(vol) else 0
    full = len(vol) > 0 and vol[k] > 0
    shares = {key: float(cols[part][k] / vol[k]) if full else None for part, key in SHARES.items()}
    return {**work_of_breathing(cols["t_s"], vol, model.arrays.lung_par), **shares}


def run_summary(
    sim, trace: Trace, *, wall_s: float, rest_return_mm, loads, error, interrupted, steps_requested: int, provenance
) -> dict:
    """The summary of a run of `sim` that recorded `trace` (`hybrid.run.run` says its keys):
    `loads` its loads observer or None, `error` the HybridError and `interrupted` the
    KeyboardInterrupt that stopped it or None, `provenance` None to make it here."""
    model = sim.model
    h = model.dt_s
    summary = {
        "scene": model.scene.name,
        "mesh_points": model.nvert,
        "status": "ok" if error is None and interrupted is None else "failed" if error else "interrupted",
        "steps": sim.steps_done,
        "dt": h,
        "duration_s": sim.time,
        "wall_s": wall_s,
        "us_per_step": wall_s / max(sim.steps_done, 1) * 1e6,
        **headline(trace),
        **(breathing_work(trace, model) if "lungs" in scene_parts(model) else {}),
        "rest_return_mm": rest_return_mm,
        "metrics": metric_table(trace),
    }
    if model.rigid is not None:  # what the rigid model runs with: the MJCF's own or the scene's
        summary["rigid"] = {
            **model.rigid.settings(),
            "timestep_s": h,
            "timestep_from": "mjcf" if model.scene.dt_s is None else "scene",
        }
    if loads is not None:
        summary["loads"] = loads.summary()
    if error is not None:
        summary["error"] = str(error)
    if interrupted is not None:
        summary["duration_requested_s"] = steps_requested * h
    summary["provenance"] = provenance if provenance is not None else run_provenance(sim)
    return summary
