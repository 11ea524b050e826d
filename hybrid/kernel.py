"""How the step's kernels are compiled.

Every step kernel is compiled without reference counting (`_nrt=False`)
and with the fast-math flags that keep NaN and infinity visible (`FAST`):
the step allocates nothing, and the atomic reference counts numba would
otherwise add around each call cost about 0.5 us per call. The per-point
passes that dominate large meshes are also compiled a second time from the
same source with `parallel=True` (their `prange` loops then run on all
cores); the model picks that build when the mesh has at least
`PARALLEL_MIN_VERTS` points, below which the threads cost more than they save.
Passes that also sum over the points take them in chunks of `CHUNK_VERTS`
consecutive points, then add the chunks' sums in order, in both builds: the
two agree to the last bit, whatever the number of threads.

Compiled code is cached on disk in a folder named after a hash of hybrid's
own sources: numba checks only a function's own file when it reuses a cached
build, so a kernel whose callee changed in another file could otherwise load
stale machine code (and crash). A changed package gets a fresh cache, and
writes into it are serialised across processes (`_lock_cache_writes`).
Folders of other versions unused for `CACHE_KEEP_DAYS` are removed at import.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import time
import types
from pathlib import Path

import numba
from numba import njit

__all__ = ["CACHE_DIR", "FAST", "FLAGS", "jit", "kernel", "kernel_twin", "CHUNK_VERTS", "PARALLEL_MIN_VERTS",
           "use_parallel", "chunk_count"]

# Fast-math without the flags that assume no NaN or infinity: fused
# multiply-adds and reciprocals, but the divergence check still sees NaN.
FAST = {"contract", "arcp", "nsz", "afn"}
# nogil: a compiled step lets other Python threads (the recorder) run meanwhile
FLAGS = dict(cache=True, error_model="numpy", _nrt=False, fastmath=FAST, nogil=True)
PARALLEL_MIN_VERTS = 2000
# points per chunk of the passes that sum over the points: long enough to
# cost nothing per chunk, short enough that the threads share evenly
CHUNK_VERTS = 64


def _cache_dir() -> str:
    """The cache folder of this exact version of hybrid's sources."""
    digest = hashlib.sha256(numba.__version__.encode())
    root = Path(__file__).resolve().parent
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "hybrid")
    return os.path.join(base, "numba-" + digest.hexdigest()[:16])


CACHE_DIR = _cache_dir()
#: cache folders of other versions of the sources unused this long are removed
CACHE_KEEP_DAYS = 30


def _prune_caches(cache_dir: str, keep_days: float, now: float) -> list[str]:
    """Mark cache_dir as used now, and remove its sibling folders of other versions
    of the sources ("numba-" and 16 hex digits) not used for keep_days: each source
    change or upgrade leaves one (5-12 MB). Returns the folders removed."""
    import re
    import shutil

    base = Path(cache_dir).parent
    try:
        Path(cache_dir).mkdir(parents=True, exist_ok=True)
        mark = Path(cache_dir) / ".last_used"
        mark.touch()
        os.utime(mark, (now, now))
        siblings = list(base.iterdir())
    except OSError:  # a read-only cache folder: numba's own problem, not ours
        return []
    removed = []
    for folder in siblings:
        if folder.name == Path(cache_dir).name or not re.fullmatch(r"numba-[0-9a-f]{16}", folder.name):
            continue
        try:
            used = folder / ".last_used"
            last = (used if used.exists() else folder).stat().st_mtime
            if now - last > keep_days * 86400:
                shutil.rmtree(folder)
                removed.append(str(folder))
        except OSError:  # in use or gone meanwhile: another process's business
            continue
    return removed


_prune_caches(CACHE_DIR, CACHE_KEEP_DAYS, time.time())


def _lock_cache_writes() -> None:
    """Serialise numba's cache writes into CACHE_DIR across processes.

    numba saves a cache entry as read index / write index / write data, with
    no lock: two processes compiling different signatures of one function at
    once (the workers of `hybrid.sweep`, or two test runs) can leave an index
    entry that points at the other's machine code, which then crashes when
    loaded. An exclusive file lock around each save makes it one step.
    """
    try:
        import fcntl
        from numba.core import caching
    except ImportError:  # no fcntl (Windows): numba's own behaviour
        return
    original = caching.IndexDataCacheFile.save
    if getattr(original, "_hybrid_locked", False):
        return

    def save(self, key, data):
        if not str(self._cache_path).startswith(CACHE_DIR):
            return original(self, key, data)
        os.makedirs(self._cache_path, exist_ok=True)
        with open(os.path.join(self._cache_path, ".lock"), "a+") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                return original(self, key, data)
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)

    save._hybrid_locked = True
    caching.IndexDataCacheFile.save = save


_lock_cache_writes()


def _start_threading_layer() -> None:
    """Start numba's threading layer before any cached kernel is loaded.

    A serial kernel (`run_membrane`) that calls the parallel twins, compiled in a
    process that loaded those twins from the cache, is saved without the hook
    that starts the threading layer (numba issue 8578). Loaded first in a new
    process, it then calls a null pointer. Starting the layer here (about 50 ms,
    once) makes every cached kernel safe to load in any order.
    """
    from numba.np.ufunc.parallel import _launch_threads

    _launch_threads()


_start_threading_layer()


@contextlib.contextmanager
def _our_cache():
    """numba reads its cache folder when a function is decorated: point it at ours meanwhile."""
    old = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = CACHE_DIR
    try:
        yield
    finally:
        numba.config.CACHE_DIR = old


def jit(fn=None, **flags):
    """`numba.njit(cache=True, **flags)` caching into `CACHE_DIR`; for compiled
    helpers outside the step (they keep numba's default flags)."""
    def wrap(f):
        with _our_cache():
            return njit(cache=True, **flags)(f)
    return wrap if fn is None else wrap(fn)


def kernel(fn=None, **extra):
    """`@kernel`: compile a step kernel with the step's flags."""
    def wrap(f):
        with _our_cache():
            return njit(**FLAGS, **extra)(f)
    return wrap if fn is None else wrap(fn)


def kernel_twin(fn, **extra):
    """(serial, parallel) builds of one kernel source. The parallel copy gets its
    own qualified name so that the two builds keep separate on-disk caches."""
    par = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_parallel", fn.__defaults__,
                             fn.__closure__)
    par.__qualname__ = fn.__qualname__ + "_parallel"
    par.__doc__ = fn.__doc__
    with _our_cache():
        return njit(**FLAGS, **extra)(fn), njit(**FLAGS, parallel=True, **extra)(par)


def chunk_count(nvert: int) -> int:
    """How many chunks of `CHUNK_VERTS` points a mesh of nvert points has."""
    return (nvert + CHUNK_VERTS - 1) // CHUNK_VERTS


def use_parallel(nvert: int) -> bool:
    """Whether a mesh of nvert points runs the parallel build."""
    return nvert >= PARALLEL_MIN_VERTS and numba.get_num_threads() > 1
