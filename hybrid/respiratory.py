"""What a run with lungs gives a respiratory physiologist, read from its trace: the
work of breathing per inspiration (elastic and resistive, from the lungs' own law),
and the lab export `respiratory.csv` (time, flow, volume, Poes, Pgas, Pdi at a chosen
sampling rate, the column layout respmech loads). An observer's module: it reads the
trace and the model's `lung_par`, never the state (docs/metrics.md, "Work of
breathing"; docs/outputs.md, "The lab export").
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .errors import HybridError
from .terms import Lungs
from .terms.lungs import CMH2O_PA, P_K1, P_K2, recoil_energy_j

__all__ = [
    "INSPIRATION_FRACTION",
    "inspirations",
    "inspiration_work",
    "work_of_breathing",
    "WORK_KEYS",
    "LAB_CSV_NAME",
    "LAB_COLUMNS",
    "lab_rate",
    "lab_export_rate",
    "lab_table",
    "write_lab_csv",
]

#: an inspiration is a rise of the lung volume by at least this fraction of the run's
#: volume swing, from a trough to a peak the volume then falls from by as much (the
#: hysteresis that keeps a ripple from splitting a breath)
INSPIRATION_FRACTION = 0.1

#: the summary's work-of-breathing keys (scenes with lungs; docs/metrics.md)
WORK_KEYS = (
    "inspirations",
    "work_of_breathing_elastic_j",
    "work_of_breathing_resistive_j",
    "work_of_breathing_j_per_l",
    "work_of_breathing_elastic_j_per_l",
    "work_of_breathing_resistive_j_per_l",
)


def inspirations(volume: np.ndarray, fraction: float = INSPIRATION_FRACTION) -> list[tuple[int, int]]:
    """The complete inspirations of a volume series, as (trough, peak) frame indices:
    the volume rises from the trough (the first frame may be one) to the peak by more
    than `fraction` of the series' swing (max - min), and falls after the peak by more
    than that before the series ends (a peak the run ends on, or a rise cut short, is
    no complete inspiration). A series that does not move has none."""
    v = np.asarray(volume, float)
    if v.size < 3 or not np.all(np.isfinite(v)):
        return []
    swing = float(v.max() - v.min())
    if not swing > 0:
        return []
    thr = fraction * swing
    found = []
    lo = hi = 0
    rising = False
    for i in range(1, v.size):
        x = v[i]
        if not rising:
            if x < v[lo]:
                lo = i
            elif x - v[lo] > thr:
                rising, hi = True, i
        else:
            if x > v[hi]:
                hi = i
            elif v[hi] - x > thr:
                found.append((lo, hi))
                rising, lo = False, i
    return found


def inspiration_work(t_s, volume_m3, lung_par) -> tuple[float, float]:
    """(elastic, resistive) work (J) done on the lungs over the frames given (one
    inspiration: times (s) and the lungs' volume above rest x (m^3)), by the model's lumped
    law (`lung_par`) P = P_L(x) - P_L0 + (K1 + K2 |Q|) Q (SI: Pa, Pa s/m^3, Pa s^2/m^6):

    W_el = integral of (P_L - P_L0) dx, exact from the recoil's energy at both ends
    (`hybrid.terms.lungs.recoil_energy_j`; E (x_end^2 - x_start^2) / 2 for the linear law);
    W_res = integral of (K1 + K2 |Q|) Q dx, each frame interval's mean flow
    q = dx / dt in the law: sum (K1 + K2 |q|) q^2 dt, low by sum K1 integral (Q - q)^2
    dt, about K1 dt^2 / 12 integral Q'^2 (relative (w dt)^2 / 12 for a sinusoid of
    angular frequency w: 2e-5 for 0.01 s frames of a 4 s breath)."""
    t = np.asarray(t_s, float)
    x = np.asarray(volume_m3, float)
    dx, dt = np.diff(x), np.diff(t)
    q = dx / dt
    k1, k2 = float(lung_par[P_K1]), float(lung_par[P_K2])
    w_el = recoil_energy_j(lung_par, x[-1]) - recoil_energy_j(lung_par, x[0])
    w_res = float(np.sum((k1 + k2 * np.abs(q)) * q * dx))
    return float(w_el), w_res


def work_of_breathing(t_s, volume_change_l, lung_par) -> dict:
    """The summary's work of breathing (`WORK_KEYS`) from the trace's times and lung
    volume change (L) and the model's `lung_par`: the number of complete inspirations
    (`inspirations`), the mean elastic and resistive work per inspiration (J), and per
    litre inspired (J/L: the sums of work over the sums of the inspirations' volume
    rises); null values without a complete inspiration."""
    t = np.asarray(t_s, float)
    x = np.asarray(volume_change_l, float) * 1e-3
    breaths = inspirations(x)
    out: dict = dict.fromkeys(WORK_KEYS)
    out["inspirations"] = len(breaths)
    if not breaths:
        return out
    w = np.array([inspiration_work(t[a : b + 1], x[a : b + 1], lung_par) for a, b in breaths])
    litres = sum((x[b] - x[a]) * 1e3 for a, b in breaths)
    el, res = w.sum(axis=0)
    out["work_of_breathing_elastic_j"] = float(el / len(breaths))
    out["work_of_breathing_resistive_j"] = float(res / len(breaths))
    out["work_of_breathing_j_per_l"] = float((el + res) / litres)
    out["work_of_breathing_elastic_j_per_l"] = float(el / litres)
    out["work_of_breathing_resistive_j_per_l"] = float(res / litres)
    return out


# ---------------------------------------------------------------- the lab export

#: the lab export's file name in the run's folder
LAB_CSV_NAME = "respiratory.csv"
#: its columns (header row), respmech's names and order: time (s), flow (L/s, inspiration
#: negative), volume (L, above rest, rising in inspiration), poes, pgas, pdi (cmH2O)
LAB_COLUMNS = ("time", "flow", "volume", "poes", "pgas", "pdi")
#: the trace's series each column is made of
LAB_SERIES = ("t_s", "flow_l_per_s", "lung_volume_change_l", "pleural_pressure_cmh2o", "pressure_pa")


def lab_rate(rate_hz, frame_dt_s: float, name: str = "--respiratory-csv", shown=None) -> float:
    """The lab export's sampling rate (Hz), checked: a finite number > 0, at most the
    run's frame rate 1 / frame_dt_s (linear interpolation between frames makes no
    finer signal); a HybridError in one line otherwise, naming `name` and what was
    received (`shown`, the text it came from, else the value)."""
    ok = isinstance(rate_hz, (int, float, np.integer, np.floating)) and not isinstance(rate_hz, bool)
    frame_hz = 1.0 / frame_dt_s
    got = repr(rate_hz) if shown is None else repr(shown)
    if not (ok and math.isfinite(rate_hz) and rate_hz > 0):
        raise HybridError(f"{name}: expected a sampling rate > 0 Hz, received {got}")
    if rate_hz > frame_hz * (1 + 1e-9):
        raise HybridError(
            f"{name}: expected a sampling rate of at most the run's frame rate, {frame_hz:.6g} Hz "
            f"(a frame every {frame_dt_s:.6g} s), received {got} Hz"
        )
    return float(rate_hz)


def lab_export_rate(text, model, frame_dt_s: float, name: str = "--respiratory-csv") -> float:
    """The lab export's rate for a run of `model` whose regular frames are frame_dt_s
    apart (`hybrid.run.frame_interval_s`), from the command line's text: a scene without
    lungs is refused, then the rate as `lab_rate` checks it; one line each."""
    if not model.arrays.term_on[Lungs.id]:
        raise HybridError(
            f'{name}: expected a scene with lungs (a force term of type "lungs"), received scene '
            f"{model.scene.name!r}, which has none"
        )
    try:
        rate = float(text)
    except (TypeError, ValueError):
        raise HybridError(f"{name}: expected a sampling rate > 0 Hz, received {text!r}") from None
    return lab_rate(rate, frame_dt_s, name, shown=text)


def lab_table(series: dict, rate_hz: float) -> np.ndarray:
    """The lab export's rows (n, 6), `LAB_COLUMNS`, sampled at t = k / rate_hz from the
    first frame's time to the last's, each column linearly interpolated in the trace's
    series (`series`: `LAB_SERIES` arrays): flow the trace's with its sign turned
    (inspiration negative), volume the lung volume change, Poes the pleural pressure,
    Pgas the abdomen's gauge pressure in cmH2O (0 where the scene has no volume term),
    Pdi = Pgas - Poes."""
    t = np.asarray(series["t_s"], float)
    if t.size == 0:
        return np.zeros((0, len(LAB_COLUMNS)))
    n = int(math.floor((t[-1] - t[0]) * rate_hz * (1 + 1e-12))) + 1
    ts = t[0] + np.arange(n) / rate_hz
    pgas_pa = np.asarray(series["pressure_pa"], float)
    if np.all(np.isnan(pgas_pa)):  # no abdominal pressure: the abdomen at its rest pressure
        pgas_pa = np.zeros_like(t)
    table = np.empty((n, len(LAB_COLUMNS)))
    table[:, 0] = ts
    table[:, 1] = -np.interp(ts, t, series["flow_l_per_s"])
    table[:, 2] = np.interp(ts, t, series["lung_volume_change_l"])
    table[:, 3] = np.interp(ts, t, series["pleural_pressure_cmh2o"])
    table[:, 4] = np.interp(ts, t, pgas_pa) / CMH2O_PA
    table[:, 5] = table[:, 4] - table[:, 3]
    return table


def write_lab_csv(trace, folder: Path, rate_hz: float) -> Path:
    """`LAB_CSV_NAME` in `folder` (replaced whole, never through a link) from the run's
    `hybrid.run.Trace` at `rate_hz` (`lab_table`): a header row of `LAB_COLUMNS`, then a
    row per sample, the time to 12 significant digits, the rest to 9 (respmech reads it with its columns time 1,
    flow 2, volume 3, poes 4, pgas 5, pdi 6, emg [], sampling frequency rate_hz)."""
    from .outputs import replaced

    table = lab_table(trace.columns(LAB_SERIES), rate_hz)
    path = Path(folder) / LAB_CSV_NAME
    with replaced(path, "w", encoding="utf-8", newline="") as f:
        f.write(",".join(LAB_COLUMNS) + "\n")
        for lo in range(0, len(table), 65536):
            np.savetxt(f, table[lo : lo + 65536], fmt=["%.12g"] + ["%.9g"] * 5, delimiter=",")
    return path
