"""How the kernels are compiled (hybrid.kernel): the compiled-code cache, a folder per
version of the kernel sources (an edit elsewhere keeps it), writes locked, entries safe
to load in any order; folders of other versions removed once unused for a while, by the
command line (not by `import hybrid`); the multi-core build of the per-point passes; and
the first run's notice, its progress counted in the CPU seconds compiling took."""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hybrid.kernel import compile_notice, prune_old_caches
from hybrid.model import compile_scene


def test_cache_folder_follows_numba_cache_dir_and_saves_are_locked(tmp_path):
    code = (
        "import hybrid.kernel as k, numba.core.caching as c; "
        "print(k.CACHE_DIR); print(getattr(c.IndexDataCacheFile.save, '_hybrid_locked', False))"
    )
    env = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    ).stdout.split()
    assert out[0].startswith(str(tmp_path / "numba-"))
    assert out[1] == "True"


def _package_copy(tmp_path) -> Path:
    import hybrid.kernel as k

    copy = tmp_path / "hybrid"
    shutil.copytree(Path(k.__file__).parent, copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


def _edit(path: Path) -> None:
    path.write_text(path.read_text() + "\n# an edit\n")


def test_the_kernel_sources_are_the_compiling_modules_and_what_they_import(tmp_path):
    import hybrid.kernel as k

    package = _package_copy(tmp_path)
    names = {p.relative_to(package).as_posix() for p in k.kernel_sources(package)}
    assert {
        "kernel.py",
        "terms/shape_memory.py",
        "terms/volume.py",
        "step.py",
        "loop.py",
        "sites.py",
        "schedule.py",
    } <= names
    assert {"errors.py", "scene.py"} <= names  # imported by kernels: their constants compile in
    assert not names & {"render.py", "cli.py", "run.py", "sweep.py", "__init__.py", "studies/cli.py"}


def test_cache_folder_follows_the_kernel_sources_only(tmp_path):
    import hybrid.kernel as k

    package = _package_copy(tmp_path)
    before = k._cache_dir(package)
    _edit(package / "render.py")  # an observer: nothing compiled changes
    _edit(package / "studies" / "cli.py")
    (package / "notes.py").write_text("import numpy\n")
    assert k._cache_dir(package) == before
    _edit(package / "terms" / "muscle.py")  # a kernel module
    after_kernel = k._cache_dir(package)
    assert after_kernel != before
    _edit(package / "scene.py")  # imported by kernel modules
    assert k._cache_dir(package) != after_kernel
    # a new module that compiles counts without being listed anywhere, and so do its imports
    (package / "notes.py").write_text("from .kernel import kernel\nfrom . import render\n")
    with_new = k._cache_dir(package)
    assert with_new != after_kernel
    _edit(package / "render.py")
    assert k._cache_dir(package) != with_new


def test_a_kernel_compiled_beside_cached_parallel_twins_loads_in_a_new_process(tmp_path):
    """numba issue 8578: a mesh above the parallel threshold caches the step with its
    parallel twins; a later process compiles the frame-capturing step beside it
    (loaded from the cache); a third process that loads that one first crashed (a
    null call, exit -11) before hybrid started numba's threading layer at import.
    (Below the threshold the twins are not compiled at all: `hybrid.step.step_par`.)"""
    env = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    large = (
        "import dataclasses, hybrid, numpy as np; from hybrid.bench import bench_membrane; "
        "model = hybrid.compile_scene(bench_membrane(4)); "
        "sim = hybrid.Simulation(dataclasses.replace(model, arrays=model.arrays._replace(parallel=True))); "
    )
    frames = large + "sim.step_frames(np.array([1, 2]), sim.frames_buffer(2))"
    for code in (large + "sim.step(2)", frames, frames):
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
        assert done.returncode == 0, (code, done.returncode, done.stderr[-2000:])


DAY = 86400.0


def _folder(base, name, last_used):
    folder = base / name
    (folder / "index").mkdir(parents=True)
    (folder / "index" / "kernel.nbi").write_bytes(b"x")
    if last_used is not None:
        (folder / ".last_used").touch()
        os.utime(folder / ".last_used", (last_used, last_used))
    return folder


def test_old_cache_folders_of_other_versions_are_removed_and_nothing_else(tmp_path):
    now = 1_800_000_000.0
    current = tmp_path / "numba-0123456789abcdef"
    old = _folder(tmp_path, "numba-aaaaaaaaaaaaaaaa", now - 31 * DAY)
    recent = _folder(tmp_path, "numba-bbbbbbbbbbbbbbbb", now - 29 * DAY)
    unmarked_old = _folder(tmp_path, "numba-cccccccccccccccc", None)  # from before the marks: its own mtime
    os.utime(unmarked_old, (now - 40 * DAY, now - 40 * DAY))
    other = _folder(tmp_path, "numba-notahash", now - 400 * DAY)  # not one of ours by name
    old_hulls = _folder(tmp_path, "hulls-dddddddddddddddd", now - 31 * DAY)  # hybrid.mesh.hulls, unused
    used_hulls = _folder(tmp_path, "hulls-eeeeeeeeeeeeeeee", now - DAY)
    removed = prune_old_caches(str(current), 30, now)
    assert sorted(removed) == sorted([str(old), str(unmarked_old), str(old_hulls)])
    assert used_hulls.exists()
    assert not old.exists() and not unmarked_old.exists()
    assert recent.exists() and other.exists()
    # the folder in use is marked as used now, and is never a candidate
    assert (current / ".last_used").stat().st_mtime == now
    assert sorted(prune_old_caches(str(current), 0, now + 10 * DAY)) == sorted([str(recent), str(used_hulls)])
    assert current.exists()


def test_the_command_line_prunes_and_import_does_not(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    old = _folder(tmp_path, "numba-aaaaaaaaaaaaaaaa", 1_000_000_000.0)
    where = "import hybrid.kernel as k; print(k.CACHE_DIR)"
    current = subprocess.run(
        [sys.executable, "-c", where], capture_output=True, text=True, env=env, check=True
    ).stdout.strip()
    mark = os.path.join(current, ".last_used")
    assert old.exists() and not os.path.exists(mark)  # import hybrid: nothing marked, nothing removed
    subprocess.run([sys.executable, "-m", "hybrid", "--help"], capture_output=True, env=env, check=True)
    assert not old.exists()
    assert os.path.exists(mark)


def test_parallel_build_matches_the_serial_build():
    """Large meshes run the multi-core build of the per-point passes
    (hybrid.kernel); its partial sums are reduced serially in the same order,
    so the two builds must agree to the last bits over a run."""

    from hybrid.bench import bench_membrane
    from hybrid.simulation import Simulation

    model = compile_scene(bench_membrane(4))  # 2562 points: above the parallel threshold
    model = model.with_dt(0.25 * model.dt_stable_s)
    from hybrid.step_work import CALL_STEPS, CALL_STEPS_PARALLEL
    from hybrid.terms.membrane import membrane_faces_parallel

    runs = {}
    for parallel in (False, True):
        sim = Simulation(model, build="parallel" if parallel else "serial")
        sim.step(200)
        assert sim.builds.steps[parallel] == 200
        # each build steps through its own build of the steps (`hybrid.loop_compile.steps_slot`): the
        # parallel one with the multi-core passes compiled in (a build without them would agree too)
        assert (sim.work.calls[CALL_STEPS_PARALLEL] != 0, sim.work.calls[CALL_STEPS] != 0) == (parallel, not parallel)
        runs[parallel] = (sim.vert_pos.copy(), sim.pressure)
    assert membrane_faces_parallel._cache._cache_file._load_index()  # compiled (here or by a helper)
    assert np.max(np.abs(runs[True][0] - runs[False][0])) <= 1e-15
    assert runs[True][1] == pytest.approx(runs[False][1], rel=1e-13)
    assert runs[True][1] != 0.0


# ---------------------------------------------------------------- the build chosen as it runs
import math

import numba

from hybrid import builds as builds_mod
from hybrid.builds import BuildChoice
from hybrid.kernel import usable_threads


def _choice(monkeypatch, **attrs) -> BuildChoice:
    """An auto choice as on a machine with 4 usable threads; class settings overridden."""
    monkeypatch.setattr(builds_mod, "usable_threads", lambda: 4)
    monkeypatch.setattr(builds_mod, "limit_threads", lambda n: None)
    for k, v in attrs.items():
        monkeypatch.setattr(BuildChoice, k, v)
    return BuildChoice(True, "auto")


def _drive(choice, us_of, nstep=10_000, calls=3):
    """Calls of nstep steps, each piece taking us_of(parallel) microseconds a step."""
    for _ in range(calls):
        left = nstep
        while left:
            par, k = choice.chunk(left)
            choice.record(par, k, k * us_of(par) * 1e-6)
            left -= k


@pytest.mark.parametrize("par_us, want_parallel", [(500.0, False), (40.0, True)])
def test_auto_runs_the_build_that_is_faster_here(monkeypatch, par_us, want_parallel):
    choice = _choice(monkeypatch)
    _drive(choice, lambda par: par_us if par else 100.0, nstep=1000)  # 0.3 s of steps: one probe
    assert choice.parallel is want_parallel and choice.probes == 1
    slow = not want_parallel
    # the probe ran the slower build for a few short pieces only: its loss is the probe's
    # (and the first step, serial, which loads the compiled code)
    assert 0 < choice.steps[slow] <= 1 + choice.PROBE_PAIRS * math.ceil(choice.PROBE_S * 1e6 / 100.0)
    assert choice.summary()["parallel_to_serial"] == pytest.approx(par_us / 100.0)


def test_auto_probes_again_within_its_budget(monkeypatch):
    choice = _choice(monkeypatch)
    _drive(choice, lambda par: 500.0 if par else 100.0, nstep=10_000, calls=200)  # 200 s of steps
    assert not choice.parallel and choice.probes > 5  # timed again now and then ...
    lost_s = choice.steps[True] * (500.0 - 100.0) * 1e-6
    assert lost_s < choice.PROBE_BUDGET * 200.0  # ... losing less than the budget


def test_auto_times_both_again_when_the_running_build_slows_down(monkeypatch):
    choice = _choice(monkeypatch, PROBE_EVERY_S=3600.0, PROBE_BUDGET=math.inf)
    _drive(choice, lambda par: 40.0 if par else 100.0, calls=1)
    assert choice.parallel and choice.probes == 1
    _drive(choice, lambda par: 40.0 if par else 100.0, calls=2)
    assert choice.probes == 1  # no new probe before PROBE_EVERY_S while nothing changes
    _drive(choice, lambda par: 900.0 if par else 100.0, calls=2)  # another program took a core
    assert not choice.parallel and choice.probes == 2


def test_fixed_builds_and_one_thread_never_probe(monkeypatch):
    for build, parallel in (("serial", False), ("parallel", True)):
        choice = BuildChoice(True, build)
        assert not choice.active and choice.chunk(1000) == (parallel, 1000)
    assert not BuildChoice(False, "auto").active  # a mesh below PARALLEL_MIN_VERTS
    with pytest.raises(ValueError, match="build"):
        BuildChoice(True, "fast")


def test_threads_respect_numba_threads_and_cpu_affinity(monkeypatch):
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)  # NUMBA_NUM_THREADS=1, or set at run time
        assert usable_threads() == 1 and not BuildChoice(True, "auto").active
    finally:
        numba.set_num_threads(threads)
    if hasattr(os, "sched_getaffinity") and threads > 1:
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})  # e.g. taskset -c 0
        try:
            choice = BuildChoice(True, "auto")
            assert usable_threads() == 1 and not choice.active
            assert numba.get_num_threads() == 1  # no more threads than CPUs to run them
        finally:
            numba.set_num_threads(threads)


def test_auto_switching_builds_mid_run_changes_no_bit(monkeypatch):
    """Probing at every call, the auto run alternates builds within calls and within
    the frames of a run; its positions and trace equal the serial run's to the bit."""

    from hybrid.bench import bench_membrane
    from hybrid.run import run
    from hybrid.simulation import Simulation

    model = compile_scene(bench_membrane(4))
    model = model.with_dt(0.25 * model.dt_stable_s)
    monkeypatch.setattr(builds_mod, "usable_threads", lambda: 2)  # a choice even where numba has one thread
    for k, v in (("PROBE_EVERY_S", 0.0), ("PROBE_BUDGET", math.inf), ("PROBE_S", 1e-9)):
        monkeypatch.setattr(BuildChoice, k, v)  # a probe at every call, pieces of one step
    traces = {}
    for build in ("serial", "auto"):
        sim = Simulation(model, build=build)
        trace = run(sim, 40 * model.dt_s, frame_dt_s=3 * model.dt_s)["trace"].arrays()
        sim.step(7)
        traces[build] = (trace, sim.vert_pos.copy())
        if build == "auto":
            assert sim.builds.steps[True] > 0 and sim.builds.steps[False] > 0 and sim.builds.probes > 3
    for key, series in traces["serial"][0].items():
        if key == "t_s":  # t0 + k h is summed per compiled call: a cut call may move its last bits
            np.testing.assert_allclose(series, traces["auto"][0][key], rtol=1e-14, atol=0)
        else:
            assert np.array_equal(series, traces["auto"][0][key], equal_nan=True), key  # NaN: a part it lacks
    assert np.array_equal(traces["serial"][1], traces["auto"][1])


class _Stream(io.StringIO):
    def __init__(self, tty: bool):
        super().__init__()
        self.tty = tty

    def isatty(self):
        return self.tty


def _wait_for(stream, text, timeout_s=30.0):
    end = time.monotonic() + timeout_s
    while text not in stream.getvalue():
        assert time.monotonic() < end, stream.getvalue()
        time.sleep(0.005)


@pytest.mark.parametrize("tty", [True, False])
def test_the_compile_notice_counts_the_compiles_cpu_against_its_estimate(tty):
    """The progress is the CPU seconds compiling took (a clock given here), against the
    estimate; past it, the notice says so instead of showing a full bar; the end line
    gives the wall and CPU time; what is not compiling (between compiles) is not counted."""
    from numba.core import event

    cpu = {"s": 100.0}
    stream = _Stream(tty)
    with compile_notice(8, stream, tick_s=0.005, line_every_s=0.01, cpu_clock=lambda: cpu["s"]):
        with event.trigger_event("numba:compile"):
            with event.trigger_event("numba:compile"):  # a callee's compile within: counted once
                cpu["s"] += 2.0
            _wait_for(stream, "2 of about 8 s of CPU")
        cpu["s"] += 50.0  # not compiling: not counted
        with event.trigger_event("numba:compile"):
            cpu["s"] += 7.0
            _wait_for(stream, "9 s of CPU, longer than the 8 s estimated")
    text = stream.getvalue()
    lines = text.replace("\r", "\n").splitlines()
    assert lines[0] == "hybrid: compiling kernels for this scene, first run only, about 8 s of CPU"
    assert re.fullmatch(
        r"hybrid: compiled in \d+\.\d s \(9\.0 s of CPU\); later runs load the kernels from .*", lines[-1]
    )
    if tty:
        assert "[#######.......................] 2 of about 8 s of CPU" in text  # 2/8 of 30 marks
        assert "[##############################] 9 s of CPU, longer than the 8 s estimated" in text
    else:
        assert "\r" not in text and "#" not in text


def test_the_compile_notice_is_silent_without_a_compile():
    stream = _Stream(False)
    with compile_notice(8, stream, tick_s=0.005):
        pass
    assert stream.getvalue() == ""


def test_the_compile_notice_announces_only_the_compiles_its_estimate_names():
    """A scene whose step loop is cached compiles a few small helpers: the notice says
    nothing before them (its estimate gives None) and only the end line; a compile the
    estimate gives a number for (another build of the loop) is announced with it."""
    from numba.core import event

    big = object()  # stands for the step loop's dispatcher
    seen = []

    def estimate(dispatcher, arg_types):
        seen.append((dispatcher, arg_types))
        return 30 if dispatcher is big else None

    stream = _Stream(False)
    with compile_notice(estimate, stream, tick_s=0.005):
        with event.trigger_event("numba:compile", data={"dispatcher": "helper", "args": ("f8",)}):
            pass
    assert seen == [("helper", ("f8",))]
    lines = stream.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hybrid: compiled in "), lines

    stream = _Stream(False)
    with compile_notice(estimate, stream, tick_s=0.005):
        with event.trigger_event("numba:compile", data={"dispatcher": "helper", "args": ()}):
            pass
        with event.trigger_event("numba:compile", data={"dispatcher": big, "args": ()}):
            pass
    lines = stream.getvalue().splitlines()
    assert lines[0] == "hybrid: compiling kernels for this scene, first run only, about 30 s of CPU", lines
    assert lines[-1].startswith("hybrid: compiled in ") and len(lines) == 2


def test_a_block_that_fails_after_unannounced_compiles_leaves_its_error_the_only_line():
    """An error (a refused --out after the scene's helpers compiled) is the command's one
    line: no end line for compiles never announced; an announced compile still ends in its
    line, failed or not."""
    from numba.core import event

    def estimate(dispatcher, arg_types):
        return 30 if dispatcher == "loop" else None

    for dispatcher, lines_expected in (("helper", 0), ("loop", 2)):
        stream = _Stream(False)
        with pytest.raises(ValueError, match="refused"):
            with compile_notice(estimate, stream, tick_s=0.005):
                with event.trigger_event("numba:compile", data={"dispatcher": dispatcher, "args": ()}):
                    pass
                raise ValueError("refused")
        lines = stream.getvalue().splitlines()
        assert len(lines) == lines_expected, (dispatcher, lines)
        if lines:
            assert lines[-1].startswith("hybrid: compiled in ")


def test_the_compile_record_keeps_this_machines_last_three_compiles(tmp_path):
    """The estimate of a kind is the median of its last three compiles; a record that cannot be
    read is started afresh; a folder that cannot be written leaves the estimate as it was."""
    from hybrid.kernel import COMPILE_RECORD, measured_compile_s, record_compile_s

    assert measured_compile_s("first run, rigid", base=tmp_path) is None
    for cpu_s in (40.0, 10.0, 30.0, 20.0):  # the first falls out: median of 10, 30, 20
        record_compile_s("first run, rigid", cpu_s, base=tmp_path)
    assert measured_compile_s("first run, rigid", base=tmp_path) == 20.0
    assert measured_compile_s("first run, implicit", base=tmp_path) is None
    record_compile_s("first run, implicit", 70.0, base=tmp_path)
    assert measured_compile_s("first run, rigid", base=tmp_path) == 20.0  # one kind does not touch another
    assert [p.name for p in tmp_path.iterdir()] == [COMPILE_RECORD]  # no temporary file left

    (tmp_path / COMPILE_RECORD).write_text("[1, 2", encoding="utf-8")  # cut short
    assert measured_compile_s("first run, rigid", base=tmp_path) is None
    record_compile_s("first run, rigid", 5.0, base=tmp_path)
    assert measured_compile_s("first run, rigid", base=tmp_path) == 5.0

    blocked = tmp_path / "a_file"
    blocked.write_text("", encoding="utf-8")
    record_compile_s("first run, rigid", 5.0, base=blocked / "cache")  # a folder inside a file: left
    assert measured_compile_s("first run, rigid", base=blocked / "cache") is None


def test_the_compile_notice_hands_on_the_cpu_of_an_announced_compile_that_ended_well():
    """on_compiled gets the CPU seconds compiling took (not the time between compiles), only
    for a compile the notice announced and a block that ended without an error."""
    from numba.core import event

    def estimate(dispatcher, arg_types):
        return 30 if dispatcher == "loop" else None

    for dispatcher, fails, expected in (("loop", False, [7.0]), ("loop", True, []), ("helper", False, [])):
        cpu, got = {"s": 0.0}, []
        with contextlib.suppress(ValueError):
            with compile_notice(
                estimate, _Stream(False), on_compiled=got.append, tick_s=0.005, cpu_clock=lambda: cpu["s"]
            ):
                with event.trigger_event("numba:compile", data={"dispatcher": dispatcher, "args": ()}):
                    cpu["s"] += 7.0
                cpu["s"] += 50.0  # not compiling
                if fails:
                    raise ValueError("refused")
        assert got == expected, (dispatcher, fails)


def test_a_first_runs_estimate_is_what_this_machine_measured_last(tmp_path, monkeypatch):
    """The command line announces a compile with the median of this machine's last compiles of
    its kind, else the package's figure, and records the one it announced."""
    import hybrid.compile_estimate as ce
    import hybrid.kernel as k
    from hybrid.loop import run_steps
    from hybrid.resolve import resolve_scene

    monkeypatch.setattr(k, "CACHE_DIR", str(tmp_path / "numba-0123456789abcdef"))
    monkeypatch.setattr(ce, "has_cached_build", lambda dispatcher: False)  # a first run
    scene = resolve_scene("breathing")  # coupled to its ribs: "first run, rigid"
    estimate, on_compiled = ce.compile_estimate(scene)
    assert estimate("helper", ()) is None
    assert estimate(run_steps, ()) == ce.COMPILE_ESTIMATE_S["first run, rigid"]
    on_compiled(9.0)
    assert k.measured_compile_s("first run, rigid") == 9.0
    k.record_compile_s("first run, rigid", 13.0)
    estimate, _ = ce.compile_estimate(scene)
    assert estimate(run_steps, ()) == 11.0  # the median of 9 and 13
    assert k.measured_compile_s("first run, membrane") is None


def test_implicit_euler_s_solve_is_announced_alone_once_the_loop_is_cached(tmp_path, monkeypatch):
    """The solve is compiled apart from the loop (`hybrid.calls.call_at`), when the simulation is
    made: with the loop cached its compile is the one announced ("implicit solve"); on an empty
    cache the first compile, the solve's or the loop's, announces the whole first run."""
    import dataclasses

    import hybrid.compile_estimate as ce
    import hybrid.kernel as k
    from hybrid.implicit import implicit_start_forces, implicit_step
    from hybrid.loop import run_steps
    from hybrid.resolve import resolve_scene

    monkeypatch.setattr(k, "CACHE_DIR", str(tmp_path / "numba-0123456789abcdef"))
    scene = dataclasses.replace(resolve_scene("breathing"), integrator="implicit_euler")
    monkeypatch.setattr(ce, "has_cached_build", lambda dispatcher: True)  # the loop cached
    estimate, _ = ce.compile_estimate(scene)
    assert estimate(implicit_step, ()) == estimate(implicit_start_forces, ()) == ce.COMPILE_ESTIMATE_S["implicit solve"]
    assert estimate(run_steps, None) is None and estimate("helper", ()) is None
    monkeypatch.setattr(ce, "has_cached_build", lambda dispatcher: False)  # an empty cache
    estimate, _ = ce.compile_estimate(scene)
    assert estimate(implicit_start_forces, ()) == ce.COMPILE_ESTIMATE_S["first run, implicit"]


def test_a_kernel_called_at_its_address_is_the_kernel_called_directly():
    """`call_at` runs the kernel `kernel_address` compiled for the arguments' types: the same
    result and the same writes as a direct call, a named tuple of arrays among the arguments (as
    the step passes its packs); a kernel whose result is not the type asked is refused."""
    from typing import NamedTuple

    from numba import njit
    from numba.core import types as nb_types

    from hybrid.calls import call_at, kernel_address

    class Pack(NamedTuple):
        x: np.ndarray
        out: np.ndarray

    @njit
    def callee(p, scale):
        total = 0.0
        for i in range(p.x.shape[0]):
            p.out[i] += scale * p.x[i] ** 2
            total += p.out[i]
        return total

    @njit
    def caller(address, p, scale):
        return call_at(address, 0.0, (p, scale))

    x = np.linspace(0.0, 1.0, 7)
    direct, apart = Pack(x, np.ones(7)), Pack(x, np.ones(7))
    address = kernel_address(callee, nb_types.float64, apart, 2.5)
    assert caller(address, apart, 2.5) == callee(direct, 2.5)
    assert np.array_equal(apart.out, direct.out) and not np.array_equal(apart.out, np.ones(7))
    with pytest.raises(TypeError, match=r"^kernel_address: .*callee returns float64, expected int64$"):
        kernel_address(callee, nb_types.int64, apart, 2.5)
