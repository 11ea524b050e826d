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
with the worker's traceback as a note) and cancels the tasks not yet started.
`on_error="return"` puts the exception object in place of the result and
carries on: the friendlier choice for studies, where one diverged case is a
result (`isinstance(r, Exception)`, e.g. `hybrid.SimulationDiverged` with its
`dt_suggested_s`). Exceptions come back with their class and attributes even
when their constructor takes keyword-only arguments.

`workers=1` runs the tasks one after the other in this process (no pickling;
for debugging).

Compiling once: the workers share the on-disk compile cache, but on a first run
each would compile the same kernels at once, each taking as long as one alone
would on the whole machine. So the first task runs alone in a worker (`_first_alone`), compiling and
caching what it needs, before the others fan out and load it: at most one round
of tasks longer when the cache is warm.
"""

from __future__ import annotations

import os
import sys
import traceback
from typing import Any, Callable, Sequence

__all__ = ["sweep", "local_workers"]


def local_workers() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _worker_init() -> None:
    """Process-pool initializer: numba on one thread (before it is imported
    when possible, else through its runtime setting)."""
    os.environ["NUMBA_NUM_THREADS"] = "1"
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
    `pickle` does not pass (e.g. SimulationDiverged)."""
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


def _call(fn: Callable, p: Any) -> tuple:
    """Run one task in a worker: ("ok", result) or ("error", packed exception)."""
    _numba_one_thread()
    try:
        return ("ok", fn(**p) if isinstance(p, dict) else fn(p))
    except Exception as exc:  # noqa: BLE001 - every task failure is reported
        try:
            import pickle
            packed = _pack_error(exc)
            pickle.dumps(packed)
        except Exception:  # an unpicklable attribute: keep class name and message
            packed = (RuntimeError, (f"{type(exc).__name__}: {exc}",), {},
                      "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
        return ("error", packed)


def _resolve(outcome: tuple, on_error: str):
    kind, value = outcome
    if kind == "ok":
        return value
    exc = _unpack_error(value)
    if on_error == "raise":
        raise exc
    return exc


def sweep(fn: Callable, params: Sequence, *, scheduler: str | None = None, workers: int | None = None,
          on_error: str = "raise") -> list:
    """`fn(**p)` (dict `p`) or `fn(p)` for every `p` in `params`, in parallel;
    the results in the order of `params`.

    scheduler  None: local processes; "tcp://HOST:PORT": an existing Dask cluster.
    workers    local processes (default: every core this process may use);
               1 runs in this process. Ignored with a scheduler.
    on_error   "raise": re-raise the first failure (in the order of params);
               "return": the exception object in place of that result.
    """
    if on_error not in ("raise", "return"):
        raise ValueError(f"on_error: expected 'raise' or 'return', received {on_error!r}")
    params = list(params)
    if not params:
        return []
    if scheduler is not None:
        return _sweep_dask(fn, params, str(scheduler), on_error)
    n = local_workers() if workers is None else int(workers)
    if n < 1:
        raise ValueError(f"workers: expected an integer >= 1, received {workers!r}")
    n = min(n, len(params))
    if n == 1:
        return [_resolve(_call(fn, p), on_error) for p in params]

    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    # children inherit the environment at start: numba on one thread from import on
    saved = os.environ.get("NUMBA_NUM_THREADS")
    os.environ["NUMBA_NUM_THREADS"] = "1"
    try:
        pool = ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("spawn"),
                                   initializer=_worker_init)
        futures = [_first_alone(pool, fn, params[0])] + [pool.submit(_call, fn, p) for p in params[1:]]
    finally:
        if saved is None:
            os.environ.pop("NUMBA_NUM_THREADS", None)
        else:
            os.environ["NUMBA_NUM_THREADS"] = saved
    try:
        return [_resolve(f.result(), on_error) for f in futures]
    finally:  # on a failure (or Ctrl-C): drop the tasks not yet started
        pool.shutdown(wait=True, cancel_futures=True)


def _first_alone(pool, fn: Callable, p: Any):
    """The first task's future, once it has finished alone in a worker: the kernels
    it compiled are then in the disk cache, where the other workers load them."""
    from concurrent.futures import wait

    future = pool.submit(_call, fn, p)
    try:
        wait([future])
    except BaseException:  # Ctrl-C: the pool goes with it
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    return future


def _sweep_dask(fn: Callable, params: list, address: str, on_error: str) -> list:
    try:
        from dask.distributed import Client
    except ImportError as exc:  # the optional extra
        raise ImportError("sweep(scheduler=...) needs dask.distributed: pip install 'hybrid[dask]'") from exc
    with Client(address, set_as_default=False) as client:
        futures = client.map(_call, [fn] * len(params), params, pure=False)
        try:
            outcomes = client.gather(futures)
            return [_resolve(o, on_error) for o in outcomes]
        finally:
            client.cancel(futures)
