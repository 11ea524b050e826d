"""The command line: `hybrid run`, `hybrid sweep`, `hybrid bench`, `hybrid render`, `hybrid view`,
`hybrid inspect`.

Bad input prints one line naming the culprit on stderr and exits with
status 2, without a traceback; a file that cannot be written (a full disk)
prints one line naming it and exits with status 74 (EX_IOERR); a run that
fails still writes what it recorded.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import math
import os
import sys
from pathlib import Path

from .compile_estimate import compile_estimate
from .errors import HybridError
from .integrators import is_implicit
from .kernel import compile_notice, prune_old_caches

__all__ = ["main"]


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, status 2 (argparse prints usage too)
        sys.stderr.write(f"hybrid: error: {message}\n")
        sys.exit(2)


def _out_arg(text: str) -> Path:
    """--out as a path: an empty one is refused (Path('') would be the current folder)."""
    if not text.strip():
        raise HybridError(f"--out: expected a folder, received {text!r}")
    return Path(text)


def _cmd_run(args) -> int:
    from .resolve import resolve_scene

    if args.own_process:
        # the collector paused while the run is set up (`_collector_resumed`): what that builds
        # (numba's registries, MuJoCo, the model) lives to the end, so a collection only walks it
        # (0.15 s of CPU of a warm 0.01 s run)
        gc.disable()

    with _figure_process(args) as drawer:
        # everything that can be refused is, before the output folder is touched
        scene = resolve_scene(args.scene, overrides=args.set or (), without=args.without or ())
        if args.dt is not None:
            scene = dataclasses.replace(scene, dt_s=args.dt)
        # a first run (nothing in the compile cache) says so before it compiles
        estimate, on_compiled = compile_estimate(scene)
        with compile_notice(estimate, on_compiled=on_compiled):
            return _load_and_run(args, scene, drawer)


def _figure_process(args):
    """As a command, the run's figure is drawn by a process of its own started now
    (`hybrid.pictures.run_figure.FigureProcess`): it imports matplotlib, about a third of
    a short warm run, on the other core while this one imports, checks and steps. Not for
    main() called in a program, which keeps its own matplotlib from one figure to the next."""
    if not args.own_process or "matplotlib.figure" in sys.modules:
        return contextlib.nullcontext(None)
    from .pictures.run_figure import FigureProcess

    return FigureProcess()


def _load_and_run(args, scene, drawer=None) -> int:
    from .model import compile_scene
    from .outputs import check_out_folder
    from .provenance import run_provenance
    from .run import claim_folder, default_out, run_steps
    from .simulation import Simulation

    duration = scene.duration_s if args.duration is None else args.duration
    out = _out_arg(args.out) if args.out is not None else default_out(scene.name)
    # before anything compiles (the folder is claimed after the checks)
    check_out_folder(out, refuse_a_run=args.out is not None and not args.overwrite)
    try:
        sim = Simulation(compile_scene(scene))
    except HybridError as exc:
        if args.duration is None or not str(exc).startswith("duration_s:"):
            raise
        # the scene's own duration is refused, but --duration replaces it: checked with that instead
        run_steps(args.duration, abs(args.duration) or 1.0)  # no finite time > 0 s: refused, named --duration
        try:
            sim = Simulation(compile_scene(dataclasses.replace(scene, duration_s=args.duration)))
        except HybridError as again:
            text = str(again)
            if text.startswith("duration_s:"):
                raise HybridError("--duration" + text[len("duration_s") :]) from None
            raise
    run_steps(duration, sim.model.dt_s, confirmed=args.yes)
    _warn_above_stable_step(sim.model)
    if getattr(args, "respiratory_csv", None) is not None:
        from .respiratory import lab_export_rate
        from .run import frame_interval_s

        args.respiratory_rate_hz = lab_export_rate(args.respiratory_csv, sim.model, frame_interval_s(sim.model.dt_s))
    if not args.no_record:
        from .record import record_steps

        record_steps(args.record_every, sim.model.dt_s, name="--record-every")
    chosen, lock = claim_folder(out, explicit=args.out is not None, overwrite=args.overwrite)
    if chosen != out:
        sys.stderr.write(f"hybrid: {out} holds an earlier run; this one goes to {chosen} (--overwrite replaces it)\n")
    provenance = run_provenance(
        sim, command=["hybrid", *args.argv], overrides=args.set or [], without=args.without or []
    )
    if args.own_process:
        _collector_resumed()
    try:
        return _run_into(args, sim, duration, chosen, provenance, drawer)
    finally:
        lock.release()


def _warn_above_stable_step(model) -> None:
    """One line before the run when an explicit integrator's step is above the per-point
    stable-step estimate (`Model.dt_stable_s`, as `hybrid inspect` reports it), and one when
    the step is above the rigid part's own (`hybrid.rigid.modes`, whatever the membrane's
    integrator): such a run diverges, and saying so at the start beats a divergence after the
    compile."""
    if model.rigid is not None:
        from .rigid.held_volumes import WARN_GAIN, held_volumes_gain, may_occlude
        from .rigid.modes import rigid_modes

        modes = rigid_modes(model.rigid.model)
        if model.dt_s > modes.dt_stable_s:
            sys.stderr.write(
                f"hybrid: warning: dt_s = {model.dt_s:g} s is above the {modes.line(model.dt_s)}: expect "
                "a divergence; set dt_s below it, or damp the mode's joints\n"
            )
        gain = held_volumes_gain(model)
        worst = gain and (gain.worst() if may_occlude(model.scene) else gain.open)
        if worst and worst >= WARN_GAIN:
            sys.stderr.write(
                f"hybrid: warning: the {gain.line()}: expect a divergence that a smaller step will not "
                "cure; make the bodies that carry the volumes heavier, or damp their joints\n"
            )
    if is_implicit(model.scene.integrator) or not math.isfinite(model.dt_stable_s):
        return
    if model.dt_s > model.dt_stable_s:
        sys.stderr.write(
            f"hybrid: warning: dt_s = {model.dt_s:g} s is above the stable-step estimate "
            f"{model.dt_stable_s:.3g} s of {model.scene.integrator}: expect a divergence; set dt_s "
            'below it, or integrator = "implicit_euler"\n'
        )


def _collector_resumed() -> None:
    """The collector on again for the run, the objects made so far frozen: never walked
    again, by the run's collections nor at the process's end (`main`)."""
    gc.freeze()
    gc.enable()


def _run_into(args, sim, duration: float, out: Path, provenance: dict, drawer=None) -> int:
    """The run, its folder locked. summary.json says "running" from the start, then
    "ok", "failed" or "interrupted": never an earlier run's. SIGINT (Ctrl-C), SIGTERM
    and SIGHUP stop the run after its current compiled call (a second one at once);
    the recording is finished whatever stopped it."""
    import os
    import signal
    import tempfile

    from .run import RunFailed, RunInterrupted, run, write_outputs, write_summary

    model = sim.model
    base = {"scene": model.scene.name, "dt": model.dt_s, "duration_requested_s": duration, "provenance": provenance}
    write_summary({**base, "status": "running", "pid": os.getpid()}, out)
    caught = []

    def as_interrupt(signum, frame):
        caught.append(signum)
        if len(caught) > 1:
            raise KeyboardInterrupt(signal.Signals(signum).name)

    stops = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous = {sig: signal.signal(sig, as_interrupt) for sig in stops}
    recorder = failure = None
    try:
        # the trace streamed to an unlinked file in the folder: memory independent of the run's length
        with tempfile.TemporaryFile(dir=out) as spill:
            try:
                # the membrane's loads on the skeleton (scenes with one) in the summary and the
                # recording: they are sampled every step, so such a run steps frame by frame
                loads = sim.model.rigid is not None
                if not args.no_record:
                    from .record import Recorder

                    recorder = Recorder(
                        out / "run.mcap", sim, every_s=args.record_every, provenance=provenance, loads=loads
                    )
                try:
                    result = run(
                        sim,
                        duration,
                        progress=True,
                        observers=[recorder] if recorder else [],
                        trace_spill=spill,
                        stop=lambda: bool(caught),
                        provenance=provenance,
                        loads=loads,
                    )
                except RunFailed as failed:
                    result, failure = failed.result, failed.error
                except RunInterrupted as interrupted:
                    result = interrupted.result
            finally:
                for sig in stops:  # a second signal must not break the finishing of the files
                    signal.signal(sig, signal.SIG_IGN)
                if recorder is not None:
                    recorder.close()
            if args.own_process:  # the figure's library lives to the end too: paused again
                gc.disable()
            write_outputs(result, out, drawer=drawer)
            if getattr(args, "respiratory_rate_hz", None) is not None:  # the trace's spill is still open here
                from .respiratory import write_lab_csv

                write_lab_csv(result["trace"], out, args.respiratory_rate_hz)
    except KeyboardInterrupt:  # before the run's loop, or in its last lines
        write_summary({**base, "status": "interrupted", "steps": sim.steps_done, "duration_s": sim.time}, out)
        return _interrupted(caught, sim, out)
    except (HybridError, OSError) as exc:
        if isinstance(exc, OSError) and not isinstance(exc, HybridError) and not exc.filename:
            from .outputs import OutputError  # a full disk under the trace's spill file: name the folder

            exc = OutputError(str(out), exc.strerror or str(exc), exc.errno or 0)
        write_summary(
            {
                **base,
                "status": "failed",
                "error": " ".join(str(exc).split()),
                "steps": sim.steps_done,
                "duration_s": sim.time,
            },
            out,
        )
        raise exc from None
    finally:
        for sig, handler in previous.items():
            # as a command (not main() called in a program), a signal after the run has ended
            # changes nothing: the summary already says how it ended, and the status agrees
            signal.signal(sig, signal.SIG_IGN if getattr(args, "own_process", False) else handler)
    s = result["summary"]
    if failure is not None:
        raise failure
    if s["status"] == "interrupted":
        return _interrupted(caught, sim, out)
    print(
        f"{s['scene']} ({s['mesh_points']}-point mesh): {s['steps']} steps of {s['dt']:g} s in {s['wall_s']:.2f} s "
        f"({s['us_per_step']:.1f} us/step); {_metrics_line(s)} -> {out}"
    )
    return 0


def _metrics_line(s: dict) -> str:
    """The summary's metrics in words, only those of the parts the scene has."""
    m = s["metrics"]
    words = []
    if s["volume_rel_error_max"] is not None:
        words.append(f"volume error max {s['volume_rel_error_max']:.1e}")
    elif "volume_rel_change" in m:
        words.append(f"volume change max {m['volume_rel_change']['max']:.1e}")
    if "rib_lift_mm" in m:
        r = m["rib_lift_mm"]
        words.append(f"rib lift {r['min']:.2f} to {r['max']:.2f} mm")
    a = m["apex_descent_mm"]
    words.append(f"apex descent {a['min']:.2f} to {a['max']:.2f} mm")
    if "pressure_pa" in m:
        words.append(f"pressure {m['pressure_pa']['min']:.0f} to {m['pressure_pa']['max']:.0f} Pa")
    if "tidal_volume_l" in s:
        words.append(f"tidal volume {s['tidal_volume_l']:.3f} L")
    if s.get("work_of_breathing_j_per_l") is not None:
        words.append(f"work of breathing {s['work_of_breathing_j_per_l']:.3g} J/L")
    return "; ".join(words)


def _interrupted(caught, sim, out: Path) -> int:
    """One line, and the shell's status for the signal (128 + its number: 130 for Ctrl-C)."""
    import signal

    signum = caught[-1] if caught else signal.SIGINT
    sys.stderr.write(
        f"hybrid: interrupted by {signal.Signals(signum).name} at t = {sim.time:.6g} s "
        f"(step {sim.steps_done}); what was recorded is in {out}\n"
    )
    return 128 + int(signum)


def _cmd_render(args) -> int:
    from .render import render
    from .run import out_folder

    result = render(
        args.source,
        out_folder(_out_arg(args.out)),
        video=args.video,
        duration_s=args.duration,
        overrides=args.set or (),
        without=args.without or (),
    )
    if result.get("died"):
        sys.stderr.write(f"hybrid: the run recorded in {args.source} was interrupted: {result['died']}\n")
    extra = f" and {result['video']}" if result["video"] else ""
    frames = ", ".join(f"{name} t = {t:.2f} s" for name, t in zip(result["titles"], result["frames"]))
    print(f"{frames} -> {result['figure']}{extra}")
    return 0


def _cmd_view(args) -> int:
    from .render import view

    shown = view(args.scene, duration_s=args.duration)
    print(
        f"viewed {shown['frames']} frames to t = {shown['t_s']:.2f} s, the membrane drawn as "
        f"{shown['membrane_geoms']} of its {shown['edges']} edges"
    )
    return 0


def _cmd_bench(args) -> int:
    from .bench import SECTIONS, format_table, run_bench

    only = tuple(s for s in args.only.split(",") if s) if args.only else None
    bad = sorted(set(only or ()) - set(SECTIONS))
    if bad:
        raise HybridError(f"--only: expected sections among {', '.join(SECTIONS)}, received {', '.join(bad)}")
    if args.realtime_level < 0:
        raise HybridError(f"--realtime-level: expected a mesh level >= 0, received {args.realtime_level}")
    result = run_bench(
        Path(args.json) if args.json else None, quick=args.quick, realtime_level=args.realtime_level, only=only
    )
    print(format_table(result))
    return 0


def _cmd_sweep(args) -> int:
    """The grid run; SIGTERM and SIGHUP stop it as Ctrl-C does: the workers ended, the
    rows finished kept in sweep.jsonl (a rerun skips them), one line, 128 + the signal."""
    import signal

    from .grid import run_grid
    from .sweep import TABLE_NAME

    out = _out_arg(args.out)
    caught = []

    def as_interrupt(signum, frame):
        caught.append(signum)
        raise KeyboardInterrupt(signal.Signals(signum).name)

    stops = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    previous = {sig: signal.signal(sig, as_interrupt) for sig in stops}
    try:
        done = run_grid(
            args.scene,
            args.set or (),
            without=args.without or (),
            duration_s=args.duration,
            out=out,
            metric=args.metric,
            workers=args.workers,
        )
    except KeyboardInterrupt:
        for sig in stops:  # the one line below, whatever comes next
            signal.signal(sig, signal.SIG_IGN)
        signum = caught[-1] if caught else signal.SIGINT
        table = out / TABLE_NAME
        kept = f"; the runs finished are in {table} (a rerun skips them)" if table.is_file() else ""
        sys.stderr.write(f"hybrid: sweep interrupted by {signal.Signals(signum).name}{kept}\n")
        return 128 + int(signum)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    print(f"{len(done['rows'])} runs, {done['failed']} failed -> {done['csv']}, {done['plot']} ({done['metric']})")
    return 1 if done["failed"] else 0


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, received {text!r}")
    return value


def _cmd_inspect(args) -> int:
    from .inspection import main_inspect

    return main_inspect(args)


def _cmd_anatomy(args) -> int:
    from .anatomy import fit_trunk

    fit = fit_trunk(
        args.model,
        args.out,
        name=args.name,
        columns=args.columns,
        clearance_m=args.clearance_m,
        dome_rise_m=args.dome_rise_m,
    )
    print("\n".join(fit.lines()))
    return 0


def _cmd_study(args) -> int:
    from .studies.cli import main_study

    return main_study(args.study_argv)


def build_parser() -> argparse.ArgumentParser:
    from .resolve import DEFAULT_SCENE, scene_names

    # the scenes a name stands for, read off the package (as the unknown-name error lists them)
    named = f"a scene TOML file, or a built-in name: {', '.join(scene_names())} (default: {DEFAULT_SCENE})"
    p = _Parser(prog="hybrid", description="Breathing trunk: MuJoCo ribs coupled to a volume-preserving membrane.")
    from . import __version__

    p.add_argument("--version", action="version", version=f"hybrid {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("run", help="run a scene (default: the built-in breathing trunk)")
    r.add_argument("scene", nargs="?", help=named)
    r.add_argument("--duration", type=float, help="simulated time (s); default: the scene's")
    r.add_argument("--dt", type=float, help="time step (s); default: the scene's")
    r.add_argument("--out", help="output folder (default runs/SCENE, or runs/SCENE-2, -3, ... when it holds a run)")
    r.add_argument(
        "--overwrite", action="store_true", help="write into the output folder even if it holds an earlier run"
    )
    r.add_argument("--yes", action="store_true", help="run even more than 1e8 steps")
    r.add_argument("--without", action="append", metavar="NAME", help="drop a force term or constraint by name")
    r.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a scene value, e.g. dt_s=5e-4")
    r.add_argument("--no-record", action="store_true", help="do not write OUT/run.mcap (the MCAP recording)")
    r.add_argument(
        "--record-every",
        type=_positive_float,
        metavar="SECONDS",
        help="recording interval in simulated time, a whole number of steps (default: the steps nearest 0.01 s)",
    )
    r.add_argument(
        "--respiratory-csv",
        metavar="HZ",
        help="also write OUT/respiratory.csv (a scene with lungs): time (s), flow (L/s, inspiration "
        "negative), volume (L), poes, pgas, pdi (cmH2O) at HZ samples a second, at most the frame rate "
        "(100 Hz), the columns respiratory mechanics software such as respmech loads",
    )
    r.set_defaults(func=_cmd_run)
    d = sub.add_parser("render", help="draw rest, peak inspiration and end of expiration (figure 4) headless")
    d.add_argument("source", nargs="?", help=f"a run.mcap recording, or {named}")
    d.add_argument("--out", required=True, help="output folder: figure4.png (and run.mp4)")
    d.add_argument("--video", action="store_true", help="also an MP4 of the run (needs pip install -e .[video])")
    d.add_argument("--duration", type=_positive_float, help="simulated time when running a scene (s)")
    d.add_argument("--without", action="append", metavar="NAME", help="drop a force term or constraint by name")
    d.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a scene value, e.g. dt_s=5e-4")
    d.set_defaults(func=_cmd_render)
    v = sub.add_parser("view", help="run a scene live in MuJoCo's viewer (needs a display)")
    v.add_argument("scene", nargs="?", help=named)
    v.add_argument("--duration", type=_positive_float, help="simulated time (s); default: the scene's")
    v.set_defaults(func=_cmd_view)
    w = sub.add_parser("sweep", help="run a scene over a grid of --set values in parallel: a table and a plot")
    w.add_argument("scene", nargs="?", help=named)
    w.add_argument("--set", action="append", metavar="KEY=V1,V2,...", help="a swept key and its values")
    w.add_argument("--without", action="append", metavar="NAME", help="drop a force term or constraint by name")
    w.add_argument("--duration", type=_positive_float, help="simulated time of each run (s); default: the scene's")
    w.add_argument("--out", required=True, help="the sweep's folder: sweep.jsonl, sweep.csv, sweep.png")
    w.add_argument("--metric", help="the summary metric plotted (default: apex_descent_mm, or the first reported)")
    w.add_argument("--workers", type=int, help="processes (default: every core this process may use)")
    w.set_defaults(func=_cmd_sweep)
    b = sub.add_parser("bench", help="time the full step; medians of repeated runs")
    b.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    b.add_argument("--quick", action="store_true", help="small sizes only (a smoke test)")
    b.add_argument(
        "--only",
        metavar="SECTION[,SECTION]",
        help="these sections only: membrane, formulations, implicit, realtime, coupled, lungs, recording, flex",
    )
    b.add_argument(
        "--realtime-level",
        type=int,
        default=8,
        metavar="K",
        help="the breathing scene's mesh level in the realtime row besides its default level 4 "
        "(default 8, the convergence study's 1%% level of all four metrics: 12 s of it take "
        "7-9 s a run here; 7 about 7 s; 4 for none)",
    )
    b.set_defaults(func=_cmd_bench)
    i = sub.add_parser(
        "inspect",
        help="what a scene or an MJCF model holds: bodies at qpos0, joints, actuators, "
        "keyframes; regions, links, nails, terms and the stable step",
    )
    i.add_argument(
        "source",
        nargs="?",
        help="a scene (TOML file or built-in name, default breathing), or an MJCF "
        'file (*.xml), "trunk" or a package model (myo_sim:myotorso)',
    )
    i.add_argument("--json", action="store_true", help="print JSON (for scripts)")
    i.add_argument("--without", action="append", metavar="NAME", help="drop a force term or constraint by name")
    i.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a scene value, e.g. dt_s=5e-4")
    i.set_defaults(func=_cmd_inspect)
    a = sub.add_parser(
        "anatomy",
        help="fit the abdomen and diaphragm to a model's rib cage, spine and pelvis: mesh files and a scene",
    )
    a.add_argument("model", help="an MJCF file, or a package model (myo_sim:myotorso), as rigid.mjcf names it")
    a.add_argument("--out", type=_out_arg, required=True, help="the folder to write into (only there)")
    a.add_argument("--name", default="fitted_trunk", help="the scene's name and file (NAME.toml)")
    a.add_argument("--columns", type=int, default=48, help="points around the trunk (even)")
    a.add_argument("--clearance-m", type=float, default=0.005, help="the membrane's distance inside the bones (m)")
    a.add_argument("--dome-rise-m", type=float, default=0.03, help="the dome's apex above the zone of apposition (m)")
    a.set_defaults(func=_cmd_anatomy)
    st = sub.add_parser(
        "study", help="numerical studies: stability, extremes, work-precision", add_help=False, prefix_chars="\0"
    )
    st.add_argument("study_argv", nargs=argparse.REMAINDER)
    st.set_defaults(func=_cmd_study)
    return p


def main(argv: list[str] | None = None) -> int:
    own = argv is None
    try:
        return _main(argv)
    finally:
        if own:
            # the command's process ends now: what it built is left to the operating system
            # rather than freed object by object by the interpreter's last collections (after a
            # warm `hybrid run`, 0.3 s of CPU and 0.5 s of wall time, mostly numba's and LLVM's
            # objects); atexit handlers still run, and every file the command wrote is closed
            gc.freeze()


def _main(argv: list[str] | None) -> int:
    prune_old_caches()
    own = argv is None
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args.own_process = own  # the command itself, not main() called by a program
    args.argv = argv  # the command line, for the run's provenance
    if own and args.command != "view":
        # MuJoCo's import loads its OpenGL binding unless MUJOCO_GL says not to (glfw, which
        # starts a Python process to read its own version: about 0.1 s of a warm `hybrid run`);
        # only `hybrid view` draws with it. A MUJOCO_GL the user set is kept.
        os.environ.setdefault("MUJOCO_GL", "disable")
    from .outputs import EXIT_IO, OutputError

    try:
        return args.func(args)
    except OutputError as exc:  # the file system refused, not the input: its own status
        sys.stderr.write(f"hybrid: error: {' '.join(str(exc).split())}\n")
        return EXIT_IO
    except HybridError as exc:
        msg = " ".join(str(exc).split())  # one line, whatever the message
        sys.stderr.write(f"hybrid: error: {msg}\n")
        return 2
    except OSError as exc:  # the file system refused (a full disk, say): what and where
        where = f" {str(exc.filename)!r}" if exc.filename else ""
        sys.stderr.write(f"hybrid: error: cannot read or write{where}: {exc.strerror or exc}\n")
        return EXIT_IO
    except KeyboardInterrupt:
        sys.stderr.write("hybrid: interrupted\n")
        return 130


if __name__ == "__main__":
    sys.exit(main())
