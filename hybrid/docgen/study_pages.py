"""The pages made from the studies' and the benchmark's JSON in docs/data/ (validation,
convergence, performance): which study each shows, and its markdown."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

from .paths import DATA

__all__ = ["Study", "STUDIES", "PAGES", "render_study_page"]


@dataclasses.dataclass(frozen=True)
class Study:
    """A study whose JSON a page shows: its `hybrid ...` command (the output folder's
    option last), the JSON file it writes there, its figures, and its markdown from
    that JSON (`markdown`: "module:function", the study's own report); `written`: the JSON
    the command writes when it is not `json_name` (two studies by one command)."""

    name: str
    command: tuple[str, ...]
    json_name: str
    markdown: str
    figures: tuple[str, ...] = ()
    title: str = ""
    how_to_read: str = ""
    written: str = ""


#: every study the pages show; `--rerun` runs each command (small unless --full)
STUDIES = {
    s.name: s
    for s in (
        Study(
            "stability",
            ("study", "stability", "--out"),
            "stability.json",
            "hybrid.studies.stability.report:markdown",
            ("stability_map.png", "membrane_spectrum.png", "self_excitation.png"),
            "Stability: the paper's section 6.1 and beyond",
            "The paper's tables of the largest stable step of a shape-memory and a mass-spring body, measured "
            "again; the stable step of the breathing membrane from its linearized step, from runs and from the "
            'per-point estimate `Model.dt_stable_s` (which `dt_s = "auto"` takes a share of); and the damping '
            "below which the non-conservative shape memory excites itself. A row reads: the case, the largest "
            "step that reached equilibrium, and the paper's value where it gives one.",
        ),
        Study(
            "verification",
            ("study", "verification", "--out"),
            "verification.json",
            "hybrid.studies.verification:markdown",
            ("verification.png",),
            "Verification of the continuum formulation",
            "The continuum terms against closed forms and conservation laws on three mesh families (UV sphere, "
            "icosphere, an irregular sphere read from STL): a pressurised sphere against the membrane's "
            "closed-form inflation, a hanging sphere, the patch test, and a free body's momenta and energy. "
            "Each row gives the measured and the predicted value and their relative error; the observed order "
            "is how fast that error falls as the mesh is refined.",
        ),
        Study(
            "rigid",
            ("study", "rigid", "--out"),
            "rigid.json",
            "hybrid.studies.rigid_check:markdown",
            (),
            "The rigid part against MuJoCo",
            "The coupled step's rigid part replayed through `mujoco.mj_step` driven by the same wrenches (the "
            "difference should be zero to the bit), and the paper's own rigid algorithm against MuJoCo's.",
        ),
        Study(
            "respiratory",
            ("study", "respiratory", "--out"),
            "respiratory.json",
            "hybrid.studies.respiratory_report:markdown",
            ("respiratory.png",),
            "Respiratory mechanics of the trunk with lungs",
            "The trunk with lungs (`breathing_lungs`) examined as a respiratory physiologist examines a subject: "
            "the passive system's compliances under steps of airway-opening pressure, the relaxation's time "
            "constant against R C (a closed form), quiet breathing against an adult's bands, an occluded "
            "twitch and the rib cage's paradox. Nothing in the scene is fitted to these figures: each is a "
            "prediction, and a row outside its band is a shortcoming of the model (the trunk is smaller than "
            "an adult's; [the lungs](lungs.md) says why each is where it is).",
        ),
        Study(
            "extremes",
            ("study", "extremes", "--out"),
            "extremes.json",
            "hybrid.studies.extremes:_markdown",
            (),
            "Stiff and extreme cases",
            "A catalogue of stiff, light, thin and badly scaled cases, each run at its stable step: it either "
            "runs, diverges with an error that says what would help, or is refused before it runs. None may "
            "run on with NaN.",
        ),
        Study(
            "convergence",
            ("study", "convergence", "--out"),
            "convergence.json",
            "hybrid.studies.convergence_report:markdown",
            ("convergence.png",),
            "Convergence of the breathing scene",
            "The breathing scene's metrics on a grid of mesh levels and time steps. Richardson extrapolation "
            "gives each metric's limit and its observed orders in space and time; the error of a run is its "
            "distance from that limit. The last table is the cheapest run (mesh level and step) whose "
            "predicted error is below each target: choose your level and step there.",
        ),
        Study(
            "convergence-lungs",
            (
                "study",
                "convergence",
                "breathing_lungs",
                "--levels",
                "5-9",
                "--duration",
                "4",
                "--integrator",
                "implicit_euler",
                "--set",
                "dt_s=0.02",
                "--repeats",
                "1",
                # the default metrics and the work of breathing, a summary number (`SUMMARY_METRICS`)
                "--metric=rib_lift_mm",
                "--metric=apex_descent_mm",
                "--metric=pressure_pa",
                "--metric=swept_volume_ml",
                "--metric=lung_volume_change_l",
                "--metric=transdiaphragmatic_pressure_change_cmh2o",
                "--metric=pleural_pressure_cmh2o:min",
                "--metric=rib_cage_pulmonary_volume_change_l",
                "--metric=rib_cage_abdominal_volume_change_l",
                "--metric=abdomen_volume_change_l",
                "--metric=work_of_breathing_j_per_l",
                "--out",
            ),
            "convergence_lungs.json",
            "hybrid.studies.convergence_report:markdown",
            (),
            "Convergence of the breathing trunk with lungs",
            "The same study of `breathing_lungs` under implicit Euler (steps of 20, 10 and 5 ms at every level, "
            "one breath), with the lungs' metrics: the lung volume change (its largest value is the first "
            "breath's tidal volume), the transdiaphragmatic pressure change, the lowest pleural pressure (end "
            "inspiration's), and the volume each wall sweeps (pulmonary rib cage, abdominal rib cage, abdomen: "
            "over the lung volume change, the Konno-Mead shares); and the work of breathing per litre inspired, "
            "a number of the run's summary. Read it as the one above.",
            written="convergence.json",
        ),
        Study(
            "work-precision",
            ("study", "work-precision", "--out"),
            "work_precision.json",
            "hybrid.studies.work_precision:_markdown",
            ("work_precision.png",),
            "Work against precision: explicit and implicit Euler",
            "Both integrators on the breathing and membrane-only scenes at a range of steps: each run's error "
            "against a reference run and its run time. A point lower and further left is better; the observed "
            "order is the slope of error against step. Where the implicit step's larger step pays for its "
            "Newton iterations, its curve crosses below the explicit one.",
        ),
        Study(
            "bench",
            ("bench", "--json"),
            "bench.json",
            "hybrid.bench:format_table",
            (),
            "The benchmark",
            "`hybrid bench`: the membrane step's cost per point and step (serial and parallel builds), the two "
            "formulations at the same step, explicit against implicit Euler, each packaged scene's realtime "
            "factor (simulated over wall time), the coupled step against MuJoCo's bare step, the breathing trunk "
            "with lungs against the same trunk without (both on the serial build), what recording costs, and "
            "MuJoCo's 2D flex beside our membrane. Medians of repeated runs; timings are of the machine named "
            "above, under its load then.",
        ),
    )
}

#: the generated pages: (title, opening text, the studies shown, in order)
PAGES = {
    "validation.md": (
        "Validation",
        "What the model reproduces of the paper and what it gets right against closed forms. Every number "
        "below is generated from the JSON file named above its table (`docs/data/`), which says the command, "
        "date, machine and version that made it; `python -m hybrid.docgen --rerun` makes them again and a test "
        "fails when this page no longer matches its JSON. Physiological ranges for the breathing scenes are on "
        "[the model](model.md) page; the history of these measurements is in the changelog.",
        ("stability", "verification", "rigid", "respiratory", "extremes"),
    ),
    "convergence.md": (
        "Error against run time",
        "How accurate a run is and what a given accuracy costs. Run the studies on your own scene "
        "(`hybrid study convergence SCENE --out DIR`, `hybrid study work-precision --out DIR`) before trusting "
        "a figure to a given number of digits. Every number below is generated from the JSON file named "
        "above its table (`docs/data/`), with the command, date, machine and version that made it.",
        ("convergence", "convergence-lungs", "work-precision"),
    ),
    "performance.md": (
        "Performance",
        "What a step costs, and how close to realtime each packaged scene runs. Timings depend on the machine "
        "and its load: run `hybrid bench` on yours. Every number below is generated from the JSON file named "
        "above its table (`docs/data/`), with the command, date, machine and version that made it.",
        ("bench",),
    ),
}


def _study_markdown(study: Study, result) -> str:
    import importlib

    module, _, function = study.markdown.partition(":")
    return getattr(importlib.import_module(module), function)(result).rstrip("\n")


def _made_by(made: dict) -> str:
    machine = made.get("machine", {})
    where = ", ".join(f"{k} {v}" for k, v in machine.items())
    commit = made.get("git_commit") or "unknown"
    return (
        f"Made by `{made['command']}` on {made['date_utc']}, hybrid {made['version']} (commit {commit[:12]}), "
        f"{made['size']} version; machine: {where}."
    )


def render_study_page(page: str, data: Path = DATA) -> str:
    """A generated page (`PAGES`) from the JSON files in `data`."""
    title, opening, names = PAGES[page]
    lines = [f"# {title}", "", "<!-- generated by python -m hybrid.docgen from docs/data/: do not edit -->", ""]
    lines += [opening, ""]
    for name in names:
        study = STUDIES[name]
        stored = json.loads((data / study.json_name).read_text(encoding="utf-8"))
        lines += [f"## {study.title}", "", study.how_to_read, ""]
        lines += [f"From [`data/{study.json_name}`](data/{study.json_name}). {_made_by(stored['made_by'])}", ""]
        text = _study_markdown(study, stored["result"])
        if name == "bench":  # a plain-text table
            text = "```\n" + text + "\n```"
        else:  # the study's own headings one level below the page's
            text = re.sub(r"^(#+) ", lambda m: "#" + m.group(1) + " ", text, flags=re.M)
        lines += [text, ""]
        for fig in study.figures:
            lines += [f"![{name}: {fig}](figures/studies/{fig})", ""]
    return "\n".join(lines)
