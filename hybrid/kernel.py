"""How the step's kernels are compiled.

Every step kernel is compiled without reference counting (`_nrt=False`)
and with the fast-math flags that keep NaN and infinity visible (`FAST`):
the step allocates nothing, and the atomic reference counts numba would
otherwise add around each call cost about 0.5 us per call. The per-point
passes that dominate large meshes are also compiled a second time from the
same source with `parallel=True` (their `prange` loops then run on all
cores). Which build runs is decided while the simulation runs (`BuildChoice`):
from `PARALLEL_MIN_VERTS` points up, with more than one usable thread, the two
builds are timed against each other in short alternating pieces of the run,
and the faster runs (`hybrid.builds.BuildChoice`): on a machine whose cores
other programs take, threads waiting for each other can make the parallel
build many times slower than one thread.
Passes that also sum over the points take them in chunks of `CHUNK_VERTS`
consecutive points, then add the chunks' sums in order, in both builds: the
two agree to the last bit, whatever the number of threads.

Compiled code is cached on disk in a folder named after a hash of the kernel
sources (`kernel_sources`: the modules that compile code and the modules they
import): numba checks only a function's own file when it reuses a cached
build, so a kernel whose callee or constant changed in another file could
otherwise load stale machine code (and crash). Changed kernels get a fresh
cache; an edit elsewhere (an observer, the command line) keeps it.

Importing this module does only what the kernels need (`_prepare_numba`: cache
writes locked across processes, numba's threading layer started). The command
line removes the cache folders of other versions (`prune_old_caches`).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shutil
import time
import types
from pathlib import Path

import numba
from numba import njit

__all__ = [
    "CACHE_DIR",
    "cache_base",
    "FAST",
    "FAST_NO_FMA",
    "FLAGS",
    "jit",
    "kernel",
    "kernel_twin",
    "CHUNK_VERTS",
    "PARALLEL_MIN_VERTS",
    "use_parallel",
    "usable_threads",
    "limit_threads",
    "chunk_count",
    "kernel_sources",
    "prune_old_caches",
    "compile_notice",
    "measured_compile_s",
    "record_compile_s",
    "has_cached_build",
    "cached_signatures",
    "numba_info",
]

# Fast-math without the flags that assume no NaN or infinity: fused
# multiply-adds and reciprocals, but the divergence check still sees NaN.
FAST = {"contract", "arcp", "nsz", "afn"}
# ... without fused multiply-adds, for kernels whose bits came out different when compiled
# than when loaded from the cache (the Newton matrix's blocks: hybrid.terms.tangent_blocks;
# level 5 of the breathing scene, implicit Euler, 60 steps: 6e-16 m apart, 0 without)
FAST_NO_FMA = {"arcp", "nsz", "afn"}
# nogil: a compiled step lets other Python threads (the recorder) run meanwhile.
# no_cfunc_wrapper: no C-callable copy of each function (nothing here takes a
# kernel's address); building one for every kernel and callee costs a first run time.
FLAGS = dict(cache=True, error_model="numpy", _nrt=False, fastmath=FAST, nogil=True, no_cfunc_wrapper=True)
# below this, a step is too short for threads to pay (their wake-up is microseconds),
# and its parallel twins are not even compiled: the breathing scene's 1,219 points step in
# 101 us serial against 554 us parallel on 2 cores, one of them busy (the run-time choice
# above this keeps measuring: `hybrid.builds`)
PARALLEL_MIN_VERTS = 2000
# points per chunk of the passes that sum over the points: long enough to
# cost nothing per chunk, short enough that the threads share evenly
CHUNK_VERTS = 64


# an import statement: "from .x import a, b as c" (names maybe in parentheses
# over several lines) or "import x.y as z"; read with a pattern, as parsing the
# package would cost 0.2 s at each import. A docstring line that looks like an
# import only adds a module to the key.
_IMPORT = re.compile(
    r"^[ \t]*(?:from[ \t]+(\.*)([\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n;#]*)"
    r"|import[ \t]+([^\n;#]*))",
    re.MULTILINE,
)


def _module_imports(source: str, module: str, is_package: bool, modules: set[str]) -> tuple[set[str], bool]:
    """The package modules a module's import statements name (at any depth), and
    whether it compiles: it imports numba, or a compiler of this module (`jit`,
    `kernel`, `kernel_twin`, or the module whole)."""
    here = f"{module.split('.')[0]}.kernel"  # this module, in the package read
    compilers = {here, f"{here}.jit", f"{here}.kernel", f"{here}.kernel_twin"}
    found, compiles = set(), False
    for dots, origin, from_names, plain_names in _IMPORT.findall(source):
        if plain_names:
            names = [name.split()[0] for name in plain_names.split(",") if name.strip()]
        else:
            if dots:  # relative: from the module's package, up len(dots) - 1
                parts = module.split(".")
                origin = ".".join(parts[: len(parts) - len(dots) + is_package] + ([origin] if origin else []))
            names = [f"{origin}.{name.split()[0]}" for name in from_names.strip("()").split(",") if name.strip()]
        for name in names:  # a module, or a name of a module
            compiles |= name == "numba" or name.startswith("numba.") or name in compilers
            found |= {name} & modules or {name.rpartition(".")[0]} & modules
    return found, compiles


def kernel_sources(package_root: Path) -> list[Path]:
    """The source files whose contents can change hybrid's compiled code: the
    modules that compile (they import numba or a compiler of this module), found
    in the sources so that a new one counts at once, and every package module
    they import (a kernel reads the constants of those when it compiles)."""
    package_root = Path(package_root)
    files = {}
    for path in sorted(package_root.rglob("*.py")):
        parts = path.relative_to(package_root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        files[".".join((package_root.name, *parts))] = path
    imports, compiles, modules = {}, set(), set(files)
    for module, path in files.items():
        source = path.read_text(encoding="utf-8", errors="replace")
        imports[module], compiling = _module_imports(source, module, path.name == "__init__.py", modules)
        if compiling:
            compiles.add(module)
    needed, todo = set(), list(compiles)
    while todo:
        module = todo.pop()
        if module not in needed:
            needed.add(module)
            todo += imports[module]
    return sorted(files[module] for module in needed)


def _cache_dir(package_root: Path = Path(__file__).resolve().parent) -> str:
    """The cache folder of this exact version of the kernel sources (and numba)."""
    digest = hashlib.sha256(numba.__version__.encode())
    for path in kernel_sources(package_root):
        digest.update(path.relative_to(package_root).as_posix().encode())
        digest.update(path.read_bytes())
    return os.path.join(cache_base(), "numba-" + digest.hexdigest()[:16])


def cache_base() -> str:
    """The folder the package's caches live in (NUMBA_CACHE_DIR, else ~/.cache/hybrid): the
    compiled kernels' folder and the other caches' (`hybrid.mesh.hulls`), each of one version."""
    return os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "hybrid"
    )


CACHE_DIR = _cache_dir()
#: cache folders of other versions of the kernel sources unused this long are removed
CACHE_KEEP_DAYS = 30


def prune_old_caches(
    cache_dir: str = CACHE_DIR, keep_days: float = CACHE_KEEP_DAYS, now: float | None = None
) -> list[str]:
    """Mark cache_dir as used now, and remove its sibling folders of other versions
    of the kernel sources ("numba-" and 16 hex digits) not used for keep_days: each
    kernel change or numba upgrade leaves one (5-12 MB); so are the convex hulls' folders
    ("hulls-", `hybrid.mesh.hulls`, which marks its own when used). Returns the folders removed."""
    now = time.time() if now is None else now
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
        if folder.name == Path(cache_dir).name or not re.fullmatch(r"(?:numba|hulls)-[0-9a-f]{16}", folder.name):
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


#: the CPU seconds of this machine's last compiles, by kind (`record_compile_s`), beside the
#: version folders: a new version's first run is announced with what the last one took here
COMPILE_RECORD = "compile_cpu_s.json"
#: compiles kept per kind; their median is the estimate (a busy machine's compile is slower)
COMPILE_RECORD_KEEP = 3


def _compile_record(base: str | None) -> Path:
    return Path(Path(CACHE_DIR).parent if base is None else base) / COMPILE_RECORD


def _read_compile_record(path: Path) -> dict:
    """The record's kinds and their CPU seconds; {} for a record absent or unreadable."""
    import json

    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if not isinstance(record, dict):
        return {}
    return {k: v for k, v in record.items() if isinstance(v, list) and all(isinstance(t, float | int) for t in v)}


def measured_compile_s(kind: str, base: str | None = None) -> float | None:
    """The median CPU seconds of the last compiles of `kind` recorded in the cache folder
    `base` (CACHE_DIR's parent), None if there is none (or the record cannot be read)."""
    import statistics

    times = _read_compile_record(_compile_record(base)).get(kind)
    return float(statistics.median(times)) if times else None


def record_compile_s(kind: str, cpu_s: float, base: str | None = None) -> None:
    """Add a compile of `kind` that took cpu_s CPU seconds to the record (the last
    COMPILE_RECORD_KEEP kept); replaced in one step, so that a reader sees the old record or the
    new; a record that cannot be read starts afresh, one that cannot be written is left."""
    import json
    import tempfile

    path = _compile_record(base)
    record = _read_compile_record(path)
    record[kind] = [*record.get(kind, []), round(float(cpu_s), 2)][-COMPILE_RECORD_KEEP:]
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".compile_cpu_s.")
    except OSError:  # a read-only cache folder: the estimate stays the package's
        return
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(record, f)
        os.replace(tmp, path)
    except OSError:  # a full disk: the old record stays
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def _prepare_numba() -> None:
    """What the kernels need from numba, done once, at this module's import.

    - Cache writes into CACHE_DIR are locked across processes. numba saves a
      cache entry as read index / write index / write data, with no lock: two
      processes compiling different signatures of one function at once (the
      workers of `hybrid.sweep`, or two test runs) can leave an index entry that
      points at the other's machine code, which then crashes when loaded. An
      exclusive file lock around each save makes it one step (where fcntl exists).
    - numba's threading layer is started before any cached kernel is loaded. A
      serial kernel (`run_membrane`) that calls the parallel twins, compiled in a
      process that loaded those twins from the cache, is saved without the hook
      that starts the threading layer (numba issue 8578); loaded first in a new
      process, it then calls a null pointer. Starting the layer here (about 50 ms)
      makes every cached kernel safe to load in any order.
    """
    from numba.core import caching
    from numba.np.ufunc.parallel import _launch_threads

    try:
        import fcntl
    except ImportError:  # no fcntl (Windows): numba's own unlocked writes
        fcntl = None
    original = caching.IndexDataCacheFile.save
    if fcntl is not None and not getattr(original, "_hybrid_locked", False):

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
    _launch_threads()


_prepare_numba()


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
    """`numba.njit(cache=True, **flags)` caching into `CACHE_DIR`, without the C-callable
    copy (`FLAGS`); for compiled helpers outside the step. Their arithmetic flags are numba's
    defaults, set explicitly: numba lets a callee that does not set `fastmath` inherit its
    caller's, so a helper the step also calls (`hybrid.sites`) would round one way compiled
    for the step and another compiled for a Python call, its bits depending on which came
    first into the cache."""
    flags.setdefault("fastmath", False)

    def wrap(f):
        with _our_cache():
            return njit(cache=True, no_cfunc_wrapper=True, **flags)(f)

    return wrap if fn is None else wrap(fn)


def kernel(fn=None, **extra):
    """`@kernel`: compile a step kernel with the step's flags (`extra` adds or replaces some)."""

    def wrap(f):
        with _our_cache():
            return njit(**{**FLAGS, **extra})(f)

    return wrap if fn is None else wrap(fn)


def kernel_twin(fn, **extra):
    """(serial, parallel) builds of one kernel source. The parallel copy gets its
    own qualified name so that the two builds keep separate on-disk caches."""
    par = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_parallel", fn.__defaults__, fn.__closure__)
    par.__qualname__ = fn.__qualname__ + "_parallel"
    par.__doc__ = fn.__doc__
    with _our_cache():
        return njit(**FLAGS, **extra)(fn), njit(**FLAGS, parallel=True, **extra)(par)


def chunk_count(nvert: int) -> int:
    """How many chunks of `CHUNK_VERTS` points a mesh of nvert points has."""
    return (nvert + CHUNK_VERTS - 1) // CHUNK_VERTS


def usable_threads() -> int:
    """The threads a parallel kernel may use here: numba's (NUMBA_NUM_THREADS, or
    `numba.set_num_threads`), at most the CPUs this process may run on (its
    affinity, `taskset`, may have changed since numba read it)."""
    n = numba.get_num_threads()
    try:
        n = min(n, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this platform
        pass
    return max(1, n)


def limit_threads(n: int) -> None:
    """numba's threads for this thread's parallel calls: at most n (never raised)."""
    if n < numba.get_num_threads():
        numba.set_num_threads(max(1, n))


def use_parallel(nvert: int) -> bool:
    """Whether a mesh of nvert points may run the parallel build (then timed
    against the serial one as it runs, `hybrid.builds.BuildChoice`)."""
    return nvert >= PARALLEL_MIN_VERTS and usable_threads() > 1


def numba_info() -> dict:
    """numba's version and the threads its parallel builds run on (for a run's provenance)."""
    return {"numba": numba.__version__, "numba_threads": numba.get_num_threads()}


def cached_signatures(dispatcher) -> list:
    """The argument types of the builds numba's disk cache holds of this compiled function for its
    current source (an index from older source holds none); none where the cache cannot be read
    (numba's cache internals: a guess, used for the compile notice and a first run's helper)."""
    try:
        return [key[0] for key in dispatcher._cache._cache_file._load_index()]
    except Exception:  # noqa: BLE001 - numba internals moved: assume nothing cached
        return []


def has_cached_build(dispatcher) -> bool:
    """Whether numba's disk cache holds a build of this compiled function, of any signature."""
    return bool(cached_signatures(dispatcher))


def process_and_helpers_cpu_s() -> float:
    """The CPU seconds of this process and of its child processes that have ended: a helper that
    compiled part of a first run (`hybrid.calls.compile_elsewhere`) counts once it is waited for."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


@contextlib.contextmanager
def compile_notice(
    estimate_cpu_s,
    stream=None,
    *,
    on_compiled=None,
    tick_s: float = 1.0,
    line_every_s: float = 10.0,
    cpu_clock=None,
):
    """Say when kernels compile within the block: at the first compile (numba's
    "numba:compile" event fires only when no build is cached, before compiling), one
    line "compiling kernels for this scene, first run only, about N s of CPU" on
    `stream` (stderr). `estimate_cpu_s`: N, or a function of the compiling function and
    its argument types giving N, or None for a compile too small to announce (counted,
    and said at the end, but the line waits for one it gives a number for); then, while compiling, the progress: the CPU seconds compiling
    has taken against the estimate (a bar redrawn on a terminal, else a line every
    10 s), which a busy machine slows but does not falsify (the wall time is shown
    beside it; past the estimate it says so instead of a full bar); at the end of the
    block the wall and CPU time it took. Nothing at all when every kernel came from the
    cache, nor when the block raises after compiles it never announced. `cpu_clock`: the
    CPU seconds compiling takes (default `process_and_helpers_cpu_s`: compiling is this process's
    main thread, the others wait, and a helper process's counts once it has ended);
    `line_every_s`: the wall seconds between lines off a terminal; `on_compiled`: called with
    the CPU seconds of an announced compile when the block ends without an error (the
    estimate's record, `record_compile_s`)."""
    import sys
    import threading

    from numba.core import event

    stream = sys.stderr if stream is None else stream
    cpu_clock = process_and_helpers_cpu_s if cpu_clock is None else cpu_clock
    tty = hasattr(stream, "isatty") and stream.isatty()
    estimate_of = estimate_cpu_s if callable(estimate_cpu_s) else (lambda dispatcher, args: estimate_cpu_s)
    state = {"depth": 0, "t0": None, "spent": 0.0, "since": None, "cpu": 0.0, "cpu_since": None, "shown": -1}
    state["said"] = False  # the first line written
    state["estimate"] = 0.0
    lock = threading.Lock()
    done = threading.Event()

    def write(text: str) -> None:
        try:
            stream.write(text)
            stream.flush()
        except (OSError, ValueError):  # a closed or broken stream: the run goes on
            pass

    def so_far() -> tuple[float, float]:
        """(wall, CPU) seconds spent compiling, the current compile included."""
        wall, cpu = state["spent"], state["cpu"]
        if state["since"] is not None:
            wall += time.perf_counter() - state["since"]
            cpu += cpu_clock() - state["cpu_since"]
        return wall, cpu

    def words(cpu: float) -> str:
        estimate = state["estimate"]
        if cpu <= estimate:
            return f"{cpu:.0f} of about {estimate:.0f} s of CPU"
        return f"{cpu:.0f} s of CPU, longer than the {estimate:.0f} s estimated"

    def progress() -> None:
        while not done.wait(tick_s):
            with lock:
                if state["since"] is None or not state["said"]:
                    continue
                wall, cpu = so_far()
            estimate = state["estimate"]
            if tty:
                n = min(int(30 * cpu / estimate), 30) if estimate > 0 else 30
                write(f"\r[{'#' * n}{'.' * (30 - n)}] {words(cpu)}, {wall:.0f} s so far")
            elif int(wall // line_every_s) > state["shown"] and wall >= line_every_s:
                state["shown"] = int(wall // line_every_s)
                write(f"hybrid: compiling, {wall:.0f} s so far ({words(cpu)})\n")

    class Notice(event.Listener):
        def on_start(self, ev):
            with lock:
                state["depth"] += 1
                if state["depth"] > 1:
                    return
                if state["t0"] is None:
                    state["t0"] = time.perf_counter()
                    threading.Thread(target=progress, name="hybrid-compile-notice", daemon=True).start()
                if not state["said"]:
                    data = ev.data or {}
                    estimate = estimate_of(data.get("dispatcher"), data.get("args"))
                    if estimate is not None:
                        state["said"], state["estimate"] = True, float(estimate)
                        write(
                            f"hybrid: compiling kernels for this scene, first run only, about {estimate:.0f} s of CPU\n"
                        )
                state["since"], state["cpu_since"] = time.perf_counter(), cpu_clock()

        def on_end(self, ev):
            with lock:
                state["depth"] -= 1
                if state["depth"] == 0 and state["since"] is not None:
                    state["spent"], state["cpu"] = so_far()
                    state["since"] = state["cpu_since"] = None

    listener = Notice()
    event.register("numba:compile", listener)
    failed = False
    try:
        yield
    except BaseException:
        failed = True
        raise
    finally:
        event.unregister("numba:compile", listener)
        done.set()
        # a block that fails after small compiles it never announced (a scene's helpers, then
        # a refused --out) ends in its error's one line, not a compile line before it
        if state["t0"] is not None and (state["said"] or not failed):
            write(
                ("\n" if tty else "") + f"hybrid: compiled in {state['spent']:.1f} s ({state['cpu']:.1f} s of CPU); "
                f"later runs load the kernels from {CACHE_DIR}\n"
            )
        if state["said"] and not failed and on_compiled is not None:
            on_compiled(state["cpu"])
