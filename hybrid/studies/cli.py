"""`hybrid study ...`: the numerical studies from the command line.

    hybrid study stability --out DIR [--small] [--scheduler ADDRESS]   # paper 6.1: DIR/stability.json, .md, PNGs
    hybrid study extremes  --out DIR [--small] [--scheduler ADDRESS]   # DIR/extremes.json, .md
    hybrid study work-precision --out DIR [--small] [--scheduler ADDRESS]
                                                 # DIR/work_precision.json, .md, .png
    hybrid study verification --out DIR [--small]  # the continuum formulation's oracles on three
                                                 # mesh families: DIR/verification.json, .md, .png
    hybrid study rigid [SCENE] --out DIR [--small]  # the rigid part against MuJoCo alone and the
                                                 # paper's rigid algorithm: DIR/rigid.json, .md
    hybrid study respiratory [SCENE] --out DIR [--small] [--level K] [--set KEY=VALUE ...]
                                                 # a scene with lungs as a physiologist examines it:
                                                 # DIR/respiratory.json, .md, .png

Studies with independent runs (work-precision) run them on all local cores,
or on an existing Dask cluster with `--scheduler tcp://HOST:PORT` (the
optional extra `hybrid[dask]`; see `hybrid.sweep`).

A folder that holds a study's earlier output (its JSON) is refused without `--overwrite`:
nothing a study wrote is replaced unasked.

`main_study(argv)` takes the arguments after `study` and returns the exit
status (0; 2 with one line on stderr for bad input, as `hybrid run`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import HybridError

__all__ = ["main_study", "build_study_parser"]


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, status 2
        sys.stderr.write(f"hybrid study: error: {message}\n")
        sys.exit(2)


def build_study_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="hybrid study", description="Numerical studies of hybrid: JSON, Markdown and plots.")
    sub = p.add_subparsers(dest="study", required=True, parser_class=_Parser)
    for name, help_ in (
        ("stability", "the paper's stability comparison (6.1) and beyond"),
        ("extremes", "a catalogue of stiff and extreme cases: stable, diverged or refused"),
        ("work-precision", "error against run time of both integrators, breathing and membrane-only scenes"),
        ("verification", "the continuum formulation against closed forms and conservation laws on three mesh families"),
        (
            "convergence",
            "a scene's metrics on a grid of mesh levels x time steps: limits, "
            "orders, and the cheapest run for 10%, 3% and 1% error",
        ),
    ):
        s = sub.add_parser(name, help=help_)
        if name == "convergence":
            s.add_argument(
                "scene",
                nargs="?",
                default="breathing",
                help="a scene whose mesh refines by level: a generated sphere or a mesh file (default: breathing)",
            )
        s.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
        s.add_argument("--small", action="store_true", help="a small version (seconds; for tests)")
        s.add_argument(
            "--scheduler",
            metavar="ADDRESS",
            default=None,
            help="run on an existing Dask cluster (tcp://HOST:PORT) instead of the local cores",
        )
        if name == "work-precision":
            s.add_argument(
                "--scene",
                default="breathing_paper",
                help="the coupled scene (default: breathing_paper, the paper's trunk at its 1 ms step)",
            )
        if name == "convergence":
            s.add_argument(
                "--repeats",
                type=int,
                default=5,
                metavar="N",
                help="a run under 1 s of CPU is run up to N times and its least CPU time kept (default 5; 1: once)",
            )
            s.add_argument(
                "--metric",
                action="append",
                metavar="NAME",
                help="a trace series whose largest value is studied, or NAME:min its smallest (repeatable; "
                "default: those of rib_lift_mm, apex_descent_mm, pressure_pa, swept_volume_ml the scene has)",
            )
            s.add_argument(
                "--levels",
                metavar="K0-K1",
                help="the mesh levels (default 0-7, --small 0-2; a mesh file: 0-2, --small 0-1)",
            )
            s.add_argument("--steps", type=int, metavar="N", help="time steps per level, halving (default 3)")
            s.add_argument(
                "--duration",
                type=float,
                metavar="S",
                help="simulated time per run (s; default 4, one breath; --small 0.5)",
            )
            s.add_argument(
                "--integrator",
                metavar="NAME",
                help="the membrane's integrator (as --set integrator=NAME; implicit_euler steps from its own "
                "step, not the explicit bound)",
            )
            s.add_argument(
                "--set",
                action="append",
                default=[],
                metavar="KEY=VALUE",
                help="a scene override for every run (e.g. mesh.generator=fibonacci_sphere)",
            )
    r = sub.add_parser(
        "rigid",
        help="a scene's rigid part: recorded wrenches replayed through MuJoCo alone, "
        "point forces against the wrench, the paper's rigid algorithm's order",
    )
    r.add_argument("scene", nargs="?", help="a scene with a rigid part (default: breathing)")
    r.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    r.add_argument("--small", action="store_true", help="200 coupled steps instead of 2000 (for tests)")
    q = sub.add_parser(
        "respiratory",
        help="a scene with lungs examined as a physiologist would: passive compliances, the relaxation's "
        "tau = R C, quiet breathing against an adult's bands, an occluded twitch, the rib cage's paradox",
    )
    q.add_argument("scene", nargs="?", default="breathing_lungs", help="a scene with lungs (default: breathing_lungs)")
    q.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    q.add_argument("--small", action="store_true", help="mesh level 0 and shorter runs (seconds; for tests)")
    q.add_argument("--level", type=int, metavar="K", help="the mesh level (default: the scene's; --small: 0)")
    q.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a scene override for every run, as hybrid run --set (e.g. rigid.ribs.sternum_stiffness_n_per_m=50)",
    )
    for study in sub.choices.values():
        study.add_argument(
            "--overwrite", action="store_true", help="write into --out even if it holds this study's earlier output"
        )
    return p


def _refuse_earlier(study: str, out: Path) -> None:
    """A folder holding this study's earlier output (its JSON) is refused without --overwrite:
    nothing a study wrote is replaced unasked."""
    earlier = out / f"{study.replace('-', '_')}.json"
    if earlier.exists():
        raise HybridError(
            f"--out: expected a folder without an earlier `hybrid study {study}`, received {str(out)!r}, "
            f"which holds {earlier.name}; pass --overwrite to replace it, or choose another folder"
        )


def _levels(text):
    """ "K0-K1" or "K0,K1,..." as a tuple of levels."""
    if text is None:
        return None
    try:
        if "-" in text:
            lo, hi = (int(x) for x in text.split("-"))
            return tuple(range(lo, hi + 1))
        return tuple(int(x) for x in text.split(","))
    except ValueError:
        raise HybridError(f"--levels: expected K0-K1 or K0,K1,... (integers), received {text!r}") from None


def _convergence(args) -> None:
    from . import convergence

    r = convergence.run(
        args.out,
        scene=args.scene,
        metrics=tuple(args.metric) if args.metric else None,
        small=args.small,
        levels=_levels(args.levels),
        nstep=args.steps,
        duration_s=args.duration,
        scheduler=args.scheduler,
        overrides=tuple(args.set) + ((f"integrator={args.integrator}",) if args.integrator else ()),
        repeats=args.repeats,
    )
    order = ", ".join(f"{k} {_num(e['observed_order_space'], '.2f')}" for k, e in r["estimate"].items() if e)
    change = ", ".join(f"{k} {v:.2%}" for k, v in r["finest_change"].items())
    basis = [row["basis"] for row in r["recommendation"]]
    rec = ", ".join(f"{basis.count(b)} {b}" for b in ("measured", "predicted", "extrapolated", "beyond") if b in basis)
    print(
        f"convergence: {len(r['runs'])} runs, {len(r['failures'])} failed; order in space: {order}; "
        f"change between the two finest levels: {change}; recommendation: {rec} (beyond: more than "
        f"{convergence.MAX_EXTRAPOLATED_LEVELS} levels past the finest run, not extrapolated); "
        f"{r['runtime_s']:.1f} s -> {args.out}/convergence.json"
    )


def _num(x, spec):
    return "-" if x is None else format(x, spec)


def _rigid(args) -> None:
    from . import rigid_check

    r = rigid_check.run(args.out, args.scene, small=args.small)
    print(
        f"rigid: {r['scene']}, {r['steps']} steps: replay max |qpos| {r['replay_max_abs_qpos']:.1e}, "
        f"|qvel| {r['replay_max_abs_qvel']:.1e}; wrench relative error {r['wrench_rel_error']:.1e}; paper "
        f"algorithm order {r['paper_algorithm_order']:.3f}; {r['runtime_s']:.1f} s -> {args.out}/rigid.json"
    )


def _respiratory(args) -> None:
    from . import respiratory

    r = respiratory.run(args.out, args.scene, small=args.small, level=args.level, overrides=tuple(args.set))
    rel = r["relaxation"]
    within = sum(bool(b["within"]) for b in r["bands"])
    print(
        f"respiratory: {r['scene']} at level {r['level']}: C_rs "
        f"{r['passive'][0]['respiratory_system_compliance_l_per_cmh2o']:.3f} L/cmH2O; tau {rel['tau_fitted_s']:.3f} s "
        f"against R C {rel['tau_rc_s']:.3f} s; tidal volume {r['quiet_breathing']['tidal_volume_l']:.3f} L; "
        f"{within} of {len(r['bands'])} figures within an adult's band; "
        f"{r['runtime_cpu_s']:.1f} s of CPU -> {args.out}/respiratory.json"
    )


def _stability(args) -> None:
    from . import stability

    r = stability.run(args.out, small=args.small, scheduler=args.scheduler)
    print(
        f"stability: Table 1 max |error| {r['table1_max_abs_error']:.1e}; Table 3 h_max "
        + ", ".join(
            f"{t['model']} {t['perturbation']} l0: {t['h_max']:.3g} (paper {t['paper_h_max']})" for t in r["table3"]
        )
        + f"; {r['runtime_s']:.1f} s -> {args.out}/stability.json"
    )


def _extremes(args) -> None:
    from . import extremes

    r = extremes.run(args.out, small=args.small, scheduler=args.scheduler)
    counts = {k: sum(c["outcome"] == k for c in r["cases"]) for k in ("stable", "diverged", "refused")}
    print(
        f"extremes: {len(r['cases'])} cases, "
        + ", ".join(f"{n} {k}" for k, n in counts.items())
        + f"; reasonable cases failing: {', '.join(r['reasonable_failures']) or 'none'}; "
        f"{len(r['bugs'])} bug(s); {r['runtime_s']:.1f} s -> {args.out}/extremes.json"
    )


def _work_precision(args) -> None:
    from . import work_precision

    r = work_precision.run(args.out, small=args.small, scheduler=args.scheduler, scene=args.scene)
    print(
        "work-precision: observed order "
        + ", ".join(f"{k} {p:.2f}" for k, p in r["order"].items())
        + "; reference converged: "
        + ", ".join(f"{s} {v['converged']}" for s, v in r["reference"].items())
        + f"; {len(r['failures'])} failed run(s); {r['runtime_s']:.1f} s -> {args.out}/work_precision.json"
    )


def _verification(args) -> None:
    from . import verification

    r = verification.run(args.out, small=args.small)
    worst = {}
    for row in r["rows"]:
        if row["rel_error"] is not None and row["oracle"] in ("pressure_sphere", "hanging_sphere"):
            worst[(row["oracle"], row["mesh_family"])] = row  # the finest level comes last
    print(
        "verification: "
        + ", ".join(f"{o} {f} {row['rel_error']:.2%} at {row['nvert']} points" for (o, f), row in worst.items())
        + f"; hanging sphere across families {r['hanging_finest_spread']:.2%}; "
        f"{r['runtime_s']:.1f} s -> {args.out}/verification.json"
    )


def main_study(argv) -> int:
    from ..run import out_folder

    args = build_study_parser().parse_args(list(argv))
    try:
        if not args.overwrite:
            _refuse_earlier(args.study, Path(args.out))
        out_folder(Path(args.out))
        {
            "stability": _stability,
            "extremes": _extremes,
            "work-precision": _work_precision,
            "verification": _verification,
            "convergence": _convergence,
            "rigid": _rigid,
            "respiratory": _respiratory,
        }[args.study](args)
        return 0
    except HybridError as exc:
        sys.stderr.write(f"hybrid study: error: {' '.join(str(exc).split())}\n")
        return 2
    except ImportError as exc:  # --scheduler without the optional extra [dask]
        sys.stderr.write(f"hybrid study: error: {exc}\n")
        return 2
    except OSError as exc:  # e.g. an output folder that cannot be created, an unreachable scheduler
        sys.stderr.write(f"hybrid study: error: {exc}\n")
        return 2
