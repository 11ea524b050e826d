"""Parameter sweeps in parallel: on all local cores, or on a Dask cluster.

>>> from hybrid.sweep import sweep
>>> results = sweep(my_run, [{"dt": 1e-3}, {"dt": 5e-4}])           # local processes
>>> results = sweep(my_run, params, scheduler="tcp://10.0.0.5:8786")  # an existing Dask cluster

`sweep(fn, params)` calls `fn(**p)` for each parameter set `p` that is a dict
(`fn(p)` for anything else) and returns the results in the order of `params`.

Local runs use a `concurrent.futures.ProcessPoolExecutor` with the 'spawn'
start method (numba's compiled code and threads are not safe across `fork`),
one worker per core by default, each with numba on one thread
(NUMBA_NUM_THREADS=1: the solver's kernels are themselves multi-core on large
meshes, and one process per core already fills the machine). `fn` and the
parameters must be picklable: a function defined at the top level of a module
(not a lambda, not in `__main__` of an interactive session). As for any
'spawn' pool, a script that calls `sweep` must guard its top level with
`if __name__ == "__main__":` (the workers import the script's module).

With `scheduler="tcp://HOST:PORT"` the tasks go to an existing Dask cluster
through `dask.distributed.Client(scheduler)` (`client.map` / `client.gather`;
the optional extra `pip install hybrid[dask]`; dask is imported only then).
The workers must be able to import `hybrid` and the module of `fn`.

Errors. `on_error="raise"` (the default) re-raises the first failure, in the
order of `params`, in the calling process (the exception object of the task,
with the worker's traceback as a note), once the tasks already running have
finished; the tasks not yet started are cancelled. `on_error="return"` puts
the exception object in place of the result and carries on: the friendlier
choice for studies, where one diverged case is a result (`isinstance(r,
Exception)`, e.g. `hybrid.SimulationDiverged` with its `dt_suggested_s`); the
exception's `sweep_params` is the task's parameter set. Exceptions come back
with their class and attributes even when their constructor takes keyword-only
arguments. A worker that dies (killed, out of memory) fails its task and the
ones not yet finished with `BrokenProcessPool`; the results already in stay.

The table. With `out=DIR`, each finished task is appended to `DIR/sweep.jsonl`
as it comes in (one JSON object a line: "params", "status" "ok" with "result",
or "failed" with "error", the exception's class and its number and string
attributes), so a sweep that is interrupted or loses a worker keeps what it
finished. A rerun into the same folder skips the parameter sets already "ok"
there, returning their results as the table holds them (JSON: lists for
arrays, the `repr` of anything JSON cannot hold), and runs the others again.

`workers=1` runs the tasks one after the other in this process (no pickling;
for debugging).

Compiling once: the workers share the on-disk compile cache, but on a first run
each would compile the same kernels at once, each taking as long as one alone
would on the whole machine. So the first task runs alone in a worker (`_first_alone`), compiling and
caching what it needs, before the others fan out and load it: at most one round
of tasks longer when the cache is warm.
"""

from __future__ import annotations

import json
import math
import operator
import os
import pickle
import sys
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["sweep", "local_workers", "TABLE_NAME"]

#: the table of finished tasks in a sweep's folder (`out`), one JSON object a line
TABLE_NAME = "sweep.jsonl"


def local_workers() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _worker_init() -> None:
    """Process-pool initializer: numba on one thread (before it is imported
    when possible, else through its runtime setting). Ctrl-C reaches the whole
    process group: a worker leaves it to the caller, which ends the workers
    (`_end_workers`), instead of dying in a traceback of its own."""
    import signal

    os.environ["NUMBA_NUM_THREADS"] = "1"
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _numba_one_thread()


def _numba_one_thread() -> None:
    if "numba" in sys.modules:
        try:
            sys.modules["numba"].set_num_threads(1)
        except Exception:  # no threading layer, or fewer threads already: fine
            pass


def _pack_error(exc: BaseException) -> tuple:
    """An exception as (class, args, attributes, traceback text): rebuilt without
    calling its constructor, which may take keyword-only arguments that
    `pickle` does not pass."""
    tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    attrs = {k: v for k, v in vars(exc).items() if k != "__notes__"}
    return (type(exc), exc.args, attrs, tb)


def _unpack_error(packed: tuple) -> BaseException:
    cls, args, attrs, tb = packed
    exc = cls.__new__(cls)
    exc.args = args
    exc.__dict__.update(attrs)
    if hasattr(exc, "add_note"):
        exc.add_note("in a sweep task:\n" + tb.rstrip())
    return exc


def _call(fn: Callable, p: Any, pickled: bool = True) -> tuple:
    """Run one task: ("ok", result) or ("error", packed exception). In a worker
    (`pickled`) the result comes as pickle's bytes, so that one that cannot be
    rebuilt in the caller fails its task rather than the pool."""
    if pickled:  # a worker; in the caller's process (workers=1) its threads stay as they are
        _numba_one_thread()
    try:
        result = fn(**p) if isinstance(p, dict) else fn(p)
    except Exception as exc:  # noqa: BLE001 - every task failure is reported
        try:
            packed = _pack_error(exc)
            if pickled:  # the caller must be able to rebuild it, or the pool breaks
                pickle.loads(pickle.dumps(packed))
        except Exception:  # an attribute that does not survive pickle: keep class name and message
            packed = (
                RuntimeError,
                (f"{type(exc).__name__}: {exc}",),
                {},
                "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)),
            )
        return ("error", packed)
    return ("ok", pickle.dumps(result) if pickled else result)


def _outcome_value(outcome: tuple, p: Any, pickled: bool):
    """The task's result, or its exception (with `sweep_params`)."""
    kind, value = outcome
    if kind == "ok":
        if not pickled:
            return value
        try:
            return pickle.loads(value)
        except Exception as exc:  # noqa: BLE001
            err: BaseException = RuntimeError(
                f"sweep: the result of the task with parameters {p!r} cannot be "
                f"rebuilt in this process: {type(exc).__name__}: {exc}"
            )
    elif kind == "error":
        err = _unpack_error(value)
    else:  # "lost": the worker died; value is the pool's exception
        err = value
        if hasattr(err, "add_note"):
            err.add_note("the worker process running this task, or another one, died (killed, out of memory)")
    try:
        err.sweep_params = p  # type: ignore[attr-defined]  # our own attribute, on an exception of any class
    except AttributeError:  # an exception class with __slots__
        pass
    return err


def _jsonable(obj):
    """obj in JSON's types: numpy arrays and numbers as lists and numbers, the
    repr of anything else JSON cannot hold."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, (int, float)):
        return obj if not isinstance(obj, float) or math.isfinite(obj) else str(obj)
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if hasattr(obj, "tolist") and hasattr(obj, "dtype"):  # numpy arrays and scalars
        return _jsonable(obj.tolist())
    return repr(obj)


def _key(p) -> str:
    return json.dumps(_jsonable(p), sort_keys=True)


class _Table:
    """DIR/sweep.jsonl: a row per finished task, appended and flushed as it comes."""

    def __init__(self, folder):
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        from .outputs import open_append, read_own

        self.path = folder / TABLE_NAME
        self.done: dict[str, Any] = {}
        text = read_own(self.path)  # a link of that name is no table of ours, and never followed
        if text is not None:
            for line in text.splitlines():
                try:
                    row = json.loads(line)
                except ValueError:  # a line cut short by a killed sweep
                    continue
                if isinstance(row, dict) and row.get("status") == "ok" and "params" in row:
                    self.done[_key(row["params"])] = row.get("result")
            self._file = open_append(self.path, encoding="utf-8")
            if text and not text.endswith("\n"):
                self._file.write("\n")
        else:
            self._file = open_append(self.path, encoding="utf-8")

    def write(self, p, value) -> None:
        row: dict = {"params": _jsonable(p)}
        if isinstance(value, BaseException):
            attrs = {k: v for k, v in vars(value).items() if isinstance(v, (int, float, str)) and k != "sweep_params"}
            row.update(
                status="failed",
                error=" ".join(str(value).split()),
                error_type=f"{type(value).__module__}.{type(value).__qualname__}",
                error_attrs=_jsonable(attrs),
            )
        else:
            row.update(status="ok", result=_jsonable(value))
        self._file.write(json.dumps(row) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()


def sweep(
    fn: Callable,
    params: Sequence,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    on_error: str = "raise",
    out=None,
) -> list:
    """`fn(**p)` (dict `p`) or `fn(p)` for every `p` in `params`, in parallel;
    the results in the order of `params`.

    scheduler  None: local processes; "tcp://HOST:PORT": an existing Dask cluster.
    workers    local processes (default: every core this process may use);
               1 runs in this process. Ignored with a scheduler.
    on_error   "raise": re-raise the first failure (in the order of params);
               "return": the exception object in place of that result, its
               `sweep_params` the task's parameters.
    out        a folder: each finished task is appended to out/sweep.jsonl as it
               comes in; the parameter sets already "ok" there are not run again.
    """
    if on_error not in ("raise", "return"):
        raise ValueError(f"on_error: expected 'raise' or 'return', received {on_error!r}")
    params = list(params)
    if not params:
        return []
    try:
        n = local_workers() if workers is None else operator.index(workers)
    except TypeError:
        n = 0
    if scheduler is None and n < 1:
        raise ValueError(f"workers: expected an integer >= 1, received {workers!r}")
    table = _Table(out) if out is not None else None
    results: list = [None] * len(params)
    todo = []
    for i, p in enumerate(params):
        if table is not None and _key(p) in table.done:
            results[i] = table.done[_key(p)]
        else:
            todo.append(i)
    failed: list[int] = []

    def finish(i: int, outcome: tuple, pickled: bool = True) -> None:
        results[i] = _outcome_value(outcome, params[i], pickled)
        if isinstance(results[i], BaseException):
            failed.append(i)
        if table is not None and outcome[0] != "lost":
            table.write(params[i], results[i])

    try:
        if not todo:
            pass
        elif scheduler is not None:
            _sweep_dask(fn, params, todo, str(scheduler), finish, on_error)
        elif min(n, len(todo)) == 1:
            for i in todo:
                finish(i, _call(fn, params[i], pickled=False), pickled=False)
                if failed and on_error == "raise":
                    break
        else:
            _sweep_local(fn, params, todo, min(n, len(todo)), finish, on_error, failed)
    finally:
        if table is not None:
            table.close()
    if failed and on_error == "raise":
        raise results[min(failed)]
    return results


def _sweep_local(fn, params, todo, n, finish, on_error, failed) -> None:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # children inherit the environment at start: numba on one thread from import on
    saved = os.environ.get("NUMBA_NUM_THREADS")
    os.environ["NUMBA_NUM_THREADS"] = "1"
    try:
        pool = ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("spawn"), initializer=_worker_init)
        # the first task alone: the kernels it compiles are then in the disk cache for the others
        futures = {_first_alone(pool, fn, params[todo[0]]): todo[0]} if todo else {}
        futures.update({pool.submit(_call, fn, params[i]): i for i in todo[1:]})
    finally:
        if saved is None:
            os.environ.pop("NUMBA_NUM_THREADS", None)
        else:
            os.environ["NUMBA_NUM_THREADS"] = saved
    taken = set()
    ended = False
    try:
        for f in as_completed(futures):
            if f.cancelled():
                continue
            taken.add(f)
            exc = f.exception()
            finish(futures[f], ("lost", exc) if exc is not None else f.result())
            if failed and on_error == "raise":
                for g in futures:  # those not yet started
                    g.cancel()
    except BaseException:  # Ctrl-C, or a signal taken as one: the workers end now, the rows in stay
        ended = True
        _end_workers(pool)
        raise
    finally:  # on a failure: drop the tasks not yet started, keep those that finish
        if not ended:
            pool.shutdown(wait=True, cancel_futures=True)
    for f, i in futures.items():
        if f not in taken and f.done() and not f.cancelled():
            exc = f.exception()
            finish(i, ("lost", exc) if exc is not None else f.result())


def _first_alone(pool, fn: Callable, p: Any):
    """The first task's future, once it has finished alone in a worker: the kernels
    it compiled are then in the disk cache, where the other workers load them."""
    from concurrent.futures import wait

    future = pool.submit(_call, fn, p)
    try:
        wait([future])
    except BaseException:  # Ctrl-C: the pool goes with it
        _end_workers(pool)
        raise
    return future


#: seconds a worker is given to end on SIGTERM before it is killed
END_WAIT_S = 3.0


def _end_workers(pool) -> None:
    """Every worker of `pool` ended (SIGTERM, then SIGKILL after `END_WAIT_S`) and the
    pool shut down, further signals ignored meanwhile: nothing is left running
    after a sweep that was interrupted, and no worker waits for its task to end."""
    import signal
    import threading
    import time

    main = threading.current_thread() is threading.main_thread()
    stops = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in stops} if main else {}
    try:
        procs = list((getattr(pool, "_processes", None) or {}).values())
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        deadline = time.monotonic() + END_WAIT_S
        for proc in procs:
            proc.join(max(deadline - time.monotonic(), 0.0))
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
        pool.shutdown(wait=False, cancel_futures=True)
        # the pool's manager thread sees its workers gone and closes its wake-up pipe; left running,
        # CPython 3.11's exit hook may write to that pipe as it closes ("Exception ignored ... Bad file
        # descriptor" on stderr after the one line, seen once in a test of SIGTERM)
        manager = getattr(pool, "_executor_manager_thread", None)
        if manager is not None:
            manager.join(END_WAIT_S)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _sweep_dask(fn: Callable, params: list, todo: list, address: str, finish, on_error: str) -> None:
    try:
        from dask.distributed import Client, as_completed
    except ImportError as exc:  # the optional extra
        raise ImportError("sweep(scheduler=...) needs dask.distributed: pip install 'hybrid[dask]'") from exc
    with Client(address, set_as_default=False) as client:
        futures = client.map(_call, [fn] * len(todo), [params[i] for i in todo], pure=False)
        index = {f.key: i for f, i in zip(futures, todo)}
        try:
            for f in as_completed(futures, loop=client.loop):
                finish(index[f.key], f.result())
        finally:
            client.cancel(futures)
