"""The command line: `hybrid run`, `hybrid bench`, `hybrid render`, `hybrid view`.

Bad input prints one line naming the culprit on stderr and exits with
status 2, without a traceback; a run that fails still writes what it
recorded.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from .errors import HybridError
from .kernel import prune_old_caches

__all__ = ["main"]


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, status 2 (argparse prints usage too)
        sys.stderr.write(f"hybrid: error: {message}\n")
        sys.exit(2)


def _cmd_run(args) -> int:
    from .model import compile_scene
    from .resolve import resolve_scene
    from .run import RunFailed, out_folder, run, write_outputs
    from .simulation import Simulation

    scene = resolve_scene(args.scene, overrides=args.set or (), without=args.without or ())
    if args.dt is not None:
        scene = dataclasses.replace(scene, dt_s=args.dt)
    duration = scene.duration_s if args.duration is None else args.duration
    if not duration > 0:
        raise HybridError(f"--duration: expected a time > 0 s, received {duration!r}")
    out = out_folder(Path(args.out) if args.out else Path("runs") / scene.name)
    sim = Simulation(compile_scene(scene))
    recorder = None
    if not args.no_record:
        from .record import Recorder
        recorder = Recorder(out / "run.mcap", sim, every_s=args.record_every)
    try:
        result = run(sim, duration, progress=True, observers=[recorder] if recorder else [])
    except RunFailed as failed:
        write_outputs(failed.result, out)
        raise failed.error
    finally:  # the recording is complete and readable whatever stopped the run
        if recorder is not None:
            recorder.close()
    write_outputs(result, out)
    s = result["summary"]
    print(f"{s['scene']}: {s['steps']} steps of {s['dt']:g} s in {s['wall_s']:.2f} s "
          f"({s['us_per_step']:.1f} us/step); volume error max {s['volume_rel_error_max']:.1e}; "
          f"rib lift {s['rib_lift_mm']:.2f} mm; apex descent {s['apex_descent_mm']:.2f} mm; "
          f"pressure {s['pressure_min_pa']:.0f} to {s['pressure_max_pa']:.0f} Pa -> {out}")
    return 0


def _cmd_render(args) -> int:
    from .render import render
    from .run import out_folder
    result = render(args.source, out_folder(Path(args.out)), video=args.video, duration_s=args.duration)
    rest, peak, end = result["frames"]
    extra = f" and {result['video']}" if result["video"] else ""
    print(f"rest t = {rest:.2f} s, peak inspiration t = {peak:.2f} s, end of expiration t = {end:.2f} s "
          f"-> {result['figure']}{extra}")
    return 0


def _cmd_view(args) -> int:
    from .render import view
    shown = view(args.scene, duration_s=args.duration)
    print(f"viewed {shown['frames']} frames to t = {shown['t_s']:.2f} s, the membrane drawn as "
          f"{shown['membrane_geoms']} of its {shown['edges']} edges")
    return 0


def _cmd_bench(args) -> int:
    from .bench import format_table, run_bench
    result = run_bench(Path(args.json) if args.json else None, quick=args.quick)
    print(format_table(result))
    return 0


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, received {text!r}")
    return value


def _cmd_study(args) -> int:
    from .studies.cli import main_study
    return main_study(args.study_argv)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="hybrid", description="Breathing trunk: MuJoCo ribs coupled to a volume-preserving membrane.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("run", help="run a scene (default: the built-in breathing trunk)")
    r.add_argument("scene", nargs="?", help="a scene TOML file, or a built-in name: breathing, membrane_demo")
    r.add_argument("--duration", type=float, help="simulated time (s); default: the scene's")
    r.add_argument("--dt", type=float, help="time step (s); default: the scene's")
    r.add_argument("--out", help="output folder (default runs/SCENE)")
    r.add_argument("--without", action="append", metavar="NAME", help="drop a force term or constraint by name")
    r.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a scene value, e.g. dt_s=5e-4")
    r.add_argument("--no-record", action="store_true", help="do not write OUT/run.mcap (the MCAP recording)")
    r.add_argument("--record-every", type=_positive_float, default=0.01, metavar="SECONDS",
                   help="recording interval in simulated time (default 0.01 s)")
    r.set_defaults(func=_cmd_run)
    d = sub.add_parser("render", help="draw rest, peak inspiration and end of expiration (figure 4) headless")
    d.add_argument("source", nargs="?", help="a run.mcap recording, or a scene to run (default: breathing)")
    d.add_argument("--out", required=True, help="output folder: figure4.png (and run.mp4)")
    d.add_argument("--video", action="store_true", help="also an MP4 of the run (needs pip install -e .[video])")
    d.add_argument("--duration", type=_positive_float, help="simulated time when running a scene (s)")
    d.set_defaults(func=_cmd_render)
    v = sub.add_parser("view", help="run a scene live in MuJoCo's viewer (needs a display)")
    v.add_argument("scene", nargs="?", help="a scene TOML file, or a built-in name (default: breathing)")
    v.add_argument("--duration", type=_positive_float, help="simulated time (s); default: the scene's")
    v.set_defaults(func=_cmd_view)
    b = sub.add_parser("bench", help="time the full step; medians of repeated runs")
    b.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    b.add_argument("--quick", action="store_true", help="small sizes only (a smoke test)")
    b.set_defaults(func=_cmd_bench)
    st = sub.add_parser("study", help="numerical studies: stability, extremes, work-precision", add_help=False, prefix_chars="\0")
    st.add_argument("study_argv", nargs=argparse.REMAINDER)
    st.set_defaults(func=_cmd_study)
    return p


def main(argv: list[str] | None = None) -> int:
    prune_old_caches()
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except HybridError as exc:
        msg = " ".join(str(exc).split())  # one line, whatever the message
        sys.stderr.write(f"hybrid: error: {msg}\n")
        return 2
    except OSError as exc:  # the file system refused (a full disk, say): what and where
        where = f" {str(exc.filename)!r}" if exc.filename else ""
        sys.stderr.write(f"hybrid: error: cannot read or write{where}: {exc.strerror or exc}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("hybrid: interrupted\n")
        return 130


if __name__ == "__main__":
    sys.exit(main())
