"""The trace: a run's time series, one row a frame and one column a series
(`TRACE_KEYS`), kept in preallocated rows or streamed to a file."""

from __future__ import annotations

import numpy as np

__all__ = ["TRACE_KEYS", "COLUMN", "SPILL_ROWS", "Trace"]


#: the trace's series, one column each (SI units unless the name says mm); a series
#: of a part the scene lacks is NaN throughout (docs/metrics.md)
TRACE_KEYS = (
    "t_s",
    "volume_m3",  # enclosed volume (closed surfaces)
    "rib_lift_mm",  # cranial (+z) displacement of the linked points' centroid (scenes with ribs)
    "apex_descent_mm",  # caudal (-z) displacement of the apex
    "volume_rel_error",  # |V - V0| / V0 under the exact volume constraint
    "pressure_pa",  # gauge pressure (scenes with a volume term)
    "muscle_n_per_m",  # the first muscle term's stiffness or fibre tension (scenes with a muscle)
    "kinetic_energy_j",
    "volume_rel_change",  # |V - V0| / V0 whatever keeps the volume (closed surfaces)
    "swept_volume_ml",  # volume the region named "diaphragm" swept inward from rest (scenes with one)
    "thorax_pitch_deg",  # the thoracic body's pitch change from its start (scenes with rigid.ribs)
    # scenes with lungs (hybrid.terms.lungs), in the respiratory physiologist's units:
    "lung_volume_change_l",  # the thoracic cavity's volume above rest
    "flow_l_per_s",  # into the lungs (inspiration positive): each step's volume change over h
    "pleural_pressure_cmh2o",  # absolute (the oesophageal pressure's model), at the last step's start
    "alveolar_pressure_cmh2o",
    "airway_opening_pressure_cmh2o",  # the scene's schedule (0: spontaneous breathing), at the last step's start
    "gastric_pressure_cmh2o",  # the abdominal pressure (the gastric pressure's model): pressure_pa in cmH2O
    "transdiaphragmatic_pressure_change_cmh2o",  # abdominal minus pleural, change from rest
    # the lung volume change's parts (Konno-Mead; optoelectronic plethysmography's compartments), L:
    "rib_cage_pulmonary_volume_change_l",  # the cavity's wall (lung change less what the floor gave)
    "rib_cage_abdominal_volume_change_l",  # swept outward by the abdomen's rib-held faces off the floor
    "abdomen_volume_change_l",  # swept outward by the abdomen's other faces off the floor
)
#: the column of each series in the trace's rows
COLUMN = {key: i for i, key in enumerate(TRACE_KEYS)}

#: rows a streamed trace holds in memory before it writes them to its file
SPILL_ROWS = 8192


class Trace:
    """Time series recorded at each frame, one row a frame and one column per key
    of `TRACE_KEYS` (`trace.t_s`, `trace.arrays()`), in a preallocated array: no
    Python object per frame. `capacity`: the rows to expect (more still fit: the
    array then doubles). `spill`: a binary file (e.g. an unlinked temporary file)
    to stream the rows to, `SPILL_ROWS` at a time, so that memory does not grow
    with the run; `arrays()` then reads them back. The running minima and maxima
    of each series (`lowest`, `highest`) and their times (`t_lowest`, `t_highest`: the
    first frame reaching them) are kept as rows come."""

    def __init__(self, capacity: int = 1024, spill=None):
        self._spill = spill
        rows = SPILL_ROWS if spill is not None else max(int(capacity), 1)
        self._buf = np.empty((rows, len(TRACE_KEYS)))
        self._held = 0  # rows in _buf
        self._written = 0  # rows in the spill file
        self.lowest = np.full(len(TRACE_KEYS), np.inf)
        self.highest = np.full(len(TRACE_KEYS), -np.inf)
        self.t_lowest = np.full(len(TRACE_KEYS), np.nan)
        self.t_highest = np.full(len(TRACE_KEYS), np.nan)
        #: what the figure needs besides the series (`run` fills it): "muscle", the label
        #: of `muscle_n_per_m`; "lung_elastance_cmh2o_per_l" and "resting_recoil_cmh2o"
        #: (scenes with lungs), for the Campbell diagram's static recoil line
        self.about: dict = {}

    def __len__(self) -> int:
        return self._written + self._held

    def reserve(self, k: int) -> np.ndarray:
        """(k, len(TRACE_KEYS)) rows to fill; they count once `commit(k)` is called,
        so that an interrupt between the two leaves the trace as it was."""
        if self._held + k > len(self._buf):
            if self._spill is not None and self._held:
                self._spill.write(self._buf[: self._held].tobytes())
                self._written += self._held
                self._held = 0
            if self._held + k > len(self._buf):
                grown = np.empty((max(2 * len(self._buf), self._held + k), len(TRACE_KEYS)))
                grown[: self._held] = self._buf[: self._held]
                self._buf = grown
        return self._buf[self._held : self._held + k]

    def commit(self, k: int) -> None:
        rows = self._buf[self._held : self._held + k]
        if k:
            cols = np.arange(len(TRACE_KEYS))
            for pick, best, when, better in (
                (rows.argmin(axis=0), self.lowest, self.t_lowest, np.less),
                (rows.argmax(axis=0), self.highest, self.t_highest, np.greater),
            ):
                value = rows[pick, cols]
                # a series of NaN (a part the scene lacks) stays NaN
                new = better(value, best) | (np.isnan(value) & ~np.isnan(best))
                best[new] = value[new]
                when[new] = rows[pick[new], 0]
        self._held += k

    def last(self, k: int) -> np.ndarray:
        """The last k rows committed (k at most the rows of the last commit), a view."""
        return self._buf[self._held - k : self._held]

    def _table(self) -> np.ndarray:
        if self._spill is None or not self._written:
            return self._buf[: self._held]
        self._spill.seek(0)
        head = np.fromfile(self._spill, dtype=float, count=self._written * len(TRACE_KEYS))
        self._spill.seek(0, 2)
        return np.concatenate([head.reshape(-1, len(TRACE_KEYS)), self._buf[: self._held]])

    def arrays(self) -> dict:
        """Every series as a float array of len(self) values: copies."""
        table = self._table()
        return {key: table[:, i].copy() for i, key in enumerate(TRACE_KEYS)}

    def columns(self, keys, every: int = 1) -> dict:
        """The series `keys` (of `TRACE_KEYS`) as float arrays, every `every`-th row from
        the first: read from the spill file a run of rows at a time, so that only those
        columns are held (the work of breathing, the lab export, the figure's diagrams)."""
        cols = [COLUMN[k] for k in keys]
        every = max(int(every), 1)
        parts = []
        start = 0  # the run's row index of the next row read
        if self._spill is not None and self._written:
            self._spill.seek(0)
            left = self._written
            while left:
                count = min(left, SPILL_ROWS)
                rows = np.fromfile(self._spill, dtype=float, count=count * len(TRACE_KEYS))
                rows = rows.reshape(-1, len(TRACE_KEYS))
                parts.append(rows[(-start) % every :: every][:, cols])
                start += count
                left -= count
            self._spill.seek(0, 2)
        parts.append(self._buf[(-start) % every : self._held : every][:, cols])
        table = np.concatenate(parts) if parts else np.empty((0, len(cols)))
        return {key: table[:, i].copy() for i, key in enumerate(keys)}

    def __getattr__(self, key):
        if key in COLUMN:
            return self._table()[:, COLUMN[key]].copy()
        raise AttributeError(key)

    def envelope(self, bins: int) -> dict:
        """Each series with at most 2 `bins` points, for a plot: the lowest and the
        highest value of each of `bins` runs of rows (every row when there are
        fewer), read from the spill file a run at a time."""
        n = len(self)
        if n <= 2 * bins:
            return self.arrays()
        per = -(-n // bins)
        parts = []

        def reduce(rows):
            for lo in range(0, len(rows), per):
                run_ = rows[lo : lo + per]
                lo_i, hi_i = run_.argmin(axis=0), run_.argmax(axis=0)
                first, second = np.minimum(lo_i, hi_i), np.maximum(lo_i, hi_i)
                cols = np.arange(len(TRACE_KEYS))
                pair = np.stack([run_[first, cols], run_[second, cols]])
                pair[:, 0] = run_[[0, -1], 0]  # time: the run's first and last
                parts.append(pair)

        if self._spill is not None and self._written:
            self._spill.seek(0)
            left, carry = self._written, np.empty((0, len(TRACE_KEYS)))
            while left:
                count = min(left, 64 * per)
                rows = np.fromfile(self._spill, dtype=float, count=count * len(TRACE_KEYS))
                rows = np.concatenate([carry, rows.reshape(-1, len(TRACE_KEYS))])
                whole = len(rows) // per * per
                reduce(rows[:whole])
                carry = rows[whole:]
                left -= count
            self._spill.seek(0, 2)
            reduce(np.concatenate([carry, self._buf[: self._held]]))
        else:
            reduce(self._buf[: self._held])
        table = np.concatenate(parts)
        return {key: table[:, i] for i, key in enumerate(TRACE_KEYS)}
