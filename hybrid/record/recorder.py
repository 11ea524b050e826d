"""The `Recorder`: an observer of the runner that copies each block of frames, holds
them in two buffers, and hands them to a writer thread that encodes and writes them
a chunk at a time, at least every `flush_s` seconds; `close()` finishes the file."""

from __future__ import annotations

import math
import queue
import threading
import time
from pathlib import Path

import numpy as np

from ..errors import HybridError
from ..loads import Loads, LoadsObserver
from ..outputs import create_new
from ..provenance import run_provenance
from ..run import TRACE_KEYS, scene_parts
from ..step import F_PRESSURE, F_TIME, F_VOLUME
from .channels import _frame_bytes_estimate, _FrameWriter, _load_slot, _nslot, _plan
from .encoder import _load_encoder
from .schemas import MESH_EVERY_FRAME_MAX, SCALAR_CHANNELS

#: the recording interval when none is given (s), as a whole number of steps
DEFAULT_EVERY_S = 0.01


def record_steps(every_s: float | None, dt_s: float, *, name: str = "every_s") -> int:
    """The steps of dt_s in a recording interval of every_s, which must be a whole
    number of them (frames are then exactly every_s apart); else a HybridError on one
    line naming the nearest steps (and intervals) that divide. None: the whole number
    of steps nearest `DEFAULT_EVERY_S`, at least one."""
    if every_s is None:
        return max(1, round(DEFAULT_EVERY_S / dt_s))
    if not (
        isinstance(every_s, (int, float)) and not isinstance(every_s, bool) and math.isfinite(every_s) and every_s > 0
    ):
        raise HybridError(f"{name}: expected a finite time > 0 s, received {every_s!r}")
    n = every_s / dt_s
    k = round(n)
    if k >= 1 and abs(n - k) <= 1e-9 * n:
        return int(k)
    lo, hi = max(math.floor(n), 1), math.floor(n) + 1
    pair = n > 1  # between two whole numbers of steps; below one, only one step fits
    steps = f"{every_s / lo:.6g} s" + (f" or {every_s / hi:.6g} s ({lo} or {hi} steps)" if pair else " (1 step)")
    intervals = f"{lo * dt_s:.6g} s" + (f" or {hi * dt_s:.6g} s" if pair else "")
    raise HybridError(
        f"{name}: expected a whole number of steps of dt_s = {dt_s:.6g} s, received {every_s:.6g} s "
        f"({n:.6g} steps); a step dt_s = {steps} divides it, or record every {intervals}"
    )


class _Frames:
    """Frames held until they are written: number (batch, nslot) = t, the scalars and
    each body's pose (copied there from xpos, xquat when written), pos (batch, nvert, 3)."""

    def __init__(self, batch: int, nvert: int, nbody: int, nslot: int):
        self.number = np.full((batch, nslot), np.nan)
        self.pos = np.empty((batch, nvert, 3))
        self.xpos = np.zeros((batch, nbody, 3))
        self.xquat = np.zeros((batch, nbody, 4))

    def numbers(self, nframe: int) -> np.ndarray:
        """The number slots of the first nframe frames, the bodies' poses filled in."""
        nbody = self.xpos.shape[1]
        if nbody:
            b0 = 1 + len(SCALAR_CHANNELS)
            body = self.number[:nframe, b0 : b0 + 7 * nbody].reshape(nframe, nbody, 7)
            body[:, :, :3] = self.xpos[:nframe]
            body[:, :, 3:] = self.xquat[:nframe]
        return self.number[:nframe]


# the trace's columns the scalar channels take, in the channels' order
_SCALAR_COLS = [TRACE_KEYS.index(key) for key in SCALAR_CHANNELS.values()]


def _named(exc: BaseException, path) -> BaseException:
    """A file system error of the recording (a full disk) as one naming its file."""
    if isinstance(exc, OSError) and not isinstance(exc, HybridError):
        from ..outputs import OutputError

        return OutputError(str(path), exc.strerror or str(exc), exc.errno or 0)
    return exc


class Recorder:
    """Write a run's frames to an MCAP file; an observer for `hybrid.run.run`.

    >>> with Recorder("run.mcap", sim) as rec:
    ...     run(sim, 12.0, observers=[rec])

    `every_s`: the recording interval in simulated time, a whole number of the
    model's steps (`record_steps`; `every_steps` of them; default: the steps nearest
    10 ms): the frames recorded are those at the multiples of it, and the runner
    offers each of them.
    `mesh_every`: the triangle list every that many recorded frames (default: 1 up to
    `MESH_EVERY_FRAME_MAX` points, 10 above); above 1, a point cloud every frame.
    `chunk_size`: bytes of an MCAP chunk, about; frames are copied as they come and
    encoded a chunk at a time, and at least every `flush_s` seconds of wall time.
    `background`: encode, compress and write on a thread of their own (the compiled
    encoder and the compressor release the GIL), so that the run goes on meanwhile.
    `flush()` writes what is held; `close()` writes the rest and finishes the file.
    `provenance`: how the run was made (`hybrid.provenance.run_provenance`; by default
    made here), written in the file's metadata (`read(path)["model"]["provenance"]`).
    `loads`: True to record the membrane's loads on the skeleton (`hybrid.loads`,
    channels /loads/...) where the scene has linked bodies or nailed regions (`hybrid
    run` does), or a `hybrid.loads.LoadsObserver`; False (default) not to. `hybrid.run`
    then fills this recorder's (`self.loads`, its summary's too) and steps frame by frame.
    """

    def __init__(
        self,
        path: str | Path,
        sim,
        *,
        every_s: float | None = None,
        mesh_every: int | None = None,
        chunk_size: int = 1 << 20,
        flush_s: float = 1.0,
        background: bool = True,
        provenance: dict | None = None,
        loads=False,
    ):
        self.every_steps = record_steps(every_s, sim.model.dt_s)
        if loads is True:  # the membrane's loads on the skeleton, where the scene has a skeleton
            found = Loads(sim)
            loads = LoadsObserver(found) if found else None
        self.loads: LoadsObserver | None = loads or None
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._dt_s = sim.model.dt_s
        self.every_s = self.every_steps * self._dt_s if every_s is None else float(every_s)
        plan = _plan(sim, self.every_s)
        plan["provenance"] = provenance if provenance is not None else run_provenance(sim)
        plan["loads"] = list(self.loads.names) if self.loads is not None else []
        # without the runner's trace: which of volume, volume error and pressure the scene has
        parts = scene_parts(sim.model)
        self._has = np.array(["closed surface" in parts, "volume constraint" in parts, "pressure" in parts])
        n = plan["nvert"]
        self.nbody = len(plan["bodies"])
        self.flush_s = flush_s
        self._last_step = -1  # the step index of the last frame recorded
        self._closed = False
        mesh_every = int(mesh_every) if mesh_every else (1 if n <= MESH_EVERY_FRAME_MAX else 10)
        _load_encoder()
        # a path that cannot be written fails here, at once; a file or link of that name is
        # replaced, a link never followed
        self._file = create_new(self.path, "wb")
        self._fw: _FrameWriter | None = None

        def make_writer() -> _FrameWriter:  # the file's head, and the encoder loaded
            return _FrameWriter(self._file, plan, chunk_size=chunk_size, mesh_every=mesh_every)

        batch = int(min(max(chunk_size // _frame_bytes_estimate(plan, mesh_every), 1), 1000))
        nslot = _nslot(self.nbody, len(plan["loads"]))
        self._load0 = _load_slot(self.nbody)
        # frames are held in one buffer while the other is written (double buffering)
        self._free: queue.Queue = queue.Queue()
        for _ in range(2 if background else 1):
            self._free.put(_Frames(batch, n, self.nbody, nslot))
        self._buf = self._free.get()
        self._sim = self._body_src = None
        self._held = 0
        self._first = 0  # the run's index of the first frame held
        self._last_flush = time.perf_counter()
        self._error: BaseException | None = None
        self._todo: queue.Queue | None = None
        if background:
            self._todo = queue.Queue()
            self._thread = threading.Thread(target=self._work, args=(make_writer,), name="hybrid-recorder", daemon=True)
            self._thread.start()
        else:
            self._fw = make_writer()

    # ------------------------------------------------------------ observer
    def __call__(self, sim, trace=None) -> None:
        """Record the current frame of `sim` if its step is a multiple of `every_steps`.
        `trace`: the runner's `Trace`, whose last row feeds the scalar channels."""
        step = sim.steps_done
        if step % self.every_steps or step <= self._last_step or self._closed:
            return
        self._last_step = step
        k = self._held
        buf = self._buf
        buf.number[k, 0] = sim.time
        buf.pos[k] = sim.state.vert_pos
        if self.nbody:
            if sim is not self._sim:
                self._sim, d = sim, sim.mj_data
                self._body_src = d.xpos[1:], d.xquat[1:]  # views of the MjData's memory
            buf.xpos[k] = self._body_src[0]
            buf.xquat[k] = self._body_src[1]
        row = buf.number[k]
        if trace is not None:
            row[1 : 1 + len(SCALAR_CHANNELS)] = trace.last(1)[0, _SCALAR_COLS]
        else:
            row[1 : 1 + len(SCALAR_CHANNELS)] = np.nan
            row[1], row[2], row[3] = sim.volume, sim.volume_rel_error, sim.pressure
            row[1:4][~self._has] = np.nan  # nothing claimed of a part the scene lacks
        self._put_loads(sim, row, step)
        self._held = k + 1
        if self._held == len(buf.pos) or time.perf_counter() - self._last_flush > self.flush_s:
            self._hand_over()

    def frames(self, sim, frames, trace=None) -> None:
        """Record the frames a compiled call captured (`hybrid.step.Frames`,
        `frames.count` of them; the trace's last rows are theirs), those at the
        multiples of `every_steps`: copied in blocks, handed over as the buffer fills."""
        k = frames.count
        if self._closed or not k:
            return
        t = frames.scal[:k, F_TIME]
        step = np.rint(t / self._dt_s).astype(np.int64)
        pick = np.flatnonzero((step % self.every_steps == 0) & (step > self._last_step))
        if len(pick):
            self._last_step = int(step[pick[-1]])
        rows = trace.last(k) if trace is not None else None
        while len(pick):
            buf, held = self._buf, self._held
            part, pick = pick[: len(buf.pos) - held], pick[len(buf.pos) - held :]
            end = held + len(part)
            buf.number[held:end, 0] = t[part]
            buf.pos[held:end] = frames.pos[part]
            if self.nbody:
                buf.xpos[held:end] = frames.body_pos[part]
                buf.xquat[held:end] = frames.body_quat[part]
            if rows is not None:
                buf.number[held:end, 1 : 1 + len(SCALAR_CHANNELS)] = rows[part][:, _SCALAR_COLS]
            else:
                vol, v0 = frames.scal[part, F_VOLUME], sim.model.arrays.vol0
                buf.number[held:end, 1 : 1 + len(SCALAR_CHANNELS)] = np.nan
                buf.number[held:end, 1] = vol
                buf.number[held:end, 2] = np.abs(vol - v0) / v0 if v0 else np.nan
                buf.number[held:end, 3] = frames.scal[part, F_PRESSURE]
                buf.number[held:end, 1:4][:, ~self._has] = np.nan
            for j, i in enumerate(part):
                self._put_loads(sim, buf.number[held + j], int(step[i]))
            self._held = end
            if end == len(buf.pos):
                self._hand_over()
        # a buffer at least half full goes now, so that the writer works while the run
        # goes on rather than after its last call
        if 2 * self._held >= len(self._buf.pos) or time.perf_counter() - self._last_flush > self.flush_s:
            self._hand_over()

    def _put_loads(self, sim, row: np.ndarray, step: int) -> None:
        """The load slots of a frame's row: the loads of sim's state if the frame is it
        (runs with loads step frame by frame), else NaN (no message)."""
        if self.loads is None:
            return
        v = self.loads.current(sim) if step == sim.steps_done else None
        row[self._load0 :] = np.nan if v is None else v.ravel()

    def _hand_over(self, last: bool = False) -> None:
        """Pass the frames held to the writer (the thread, or now); `last`: no frames follow."""
        if self._held:
            item = (self._buf, self._held, self._first)
            self._first += self._held
            self._held = 0
            if self._todo is not None:
                self._todo.put(item)
                if not last:
                    self._buf = self._free.get()  # waits while both buffers are being written
            else:
                self._write(item)
        self._last_flush = time.perf_counter()
        if self._error is not None:
            raise self._error

    def _write(self, item) -> None:
        buf, nframe, first = item
        try:
            if self._error is None:
                number = buf.numbers(nframe)
                self._fw.write(number[:, 0], number, buf.pos[:nframe], first)
        except BaseException as exc:  # raised again in the run's thread
            self._error = _named(exc, self.path)
        finally:
            if self._todo is not None:
                self._free.put(item[0])
            else:
                self._buf = item[0]

    def _work(self, make_writer) -> None:
        while True:
            item = self._todo.get()
            if self._fw is None and self._error is None:
                # the file's head, once the first frames come: the run is then in its
                # compiled steps (which release the GIL), so this costs it nothing
                try:
                    self._fw = make_writer()
                except BaseException as exc:  # raised again in the run's thread
                    self._error = _named(exc, self.path)
            try:
                if item is None:
                    return
                self._write(item)
            finally:
                self._todo.task_done()

    def flush(self) -> None:
        """Write the frames held, and wait until they are in the file."""
        self._hand_over()
        if self._todo is not None:
            self._todo.join()
        if self._error is not None:
            raise self._error

    # ------------------------------------------------------------ closing
    def close(self) -> None:
        """Finish the file: the frames held, then summary and footer. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            try:
                self._hand_over(last=True)
            finally:
                if self._todo is not None:
                    self._todo.put(None)
                    self._thread.join()
        finally:
            try:
                if self._fw is not None:
                    self._fw.close()
                else:
                    self._file.close()
            except OSError as exc:  # the last bytes refused (a full disk): named, after any earlier error
                if self._error is None:
                    raise _named(exc, self.path) from None
        if self._error is not None:
            raise self._error

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
