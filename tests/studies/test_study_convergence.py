"""`hybrid study convergence`: Richardson extrapolation recovers closed-form limits and
orders, and the small study runs the breathing scene on a grid of levels x steps."""

from __future__ import annotations

import copy
import importlib.util
import math

import pytest
from helpers import strict_load

from hybrid.studies.cli import main_study
from hybrid.studies.convergence import (
    DEFAULT_METRICS,
    LUNG_METRICS,
    MAX_EXTRAPOLATED_LEVELS,
    RATIO_SPACE,
    TARGETS,
    estimate,
    recommend,
    richardson,
)
from hybrid.studies.convergence_report import markdown


def test_richardson_recovers_the_limit_and_order_of_a_power_law():
    r = math.sqrt(2.0)
    for p in (1.0, 2.0):
        xs = [3.0 + 0.7 * (0.1 / r**k) ** p for k in range(4)]
        limit, observed, used = richardson(xs, r)
        assert observed == pytest.approx(p, rel=1e-9) and used == observed
        assert limit == pytest.approx(3.0, rel=1e-12)
    # two values: first order assumed (the integrators' order)
    assert richardson([2.0, 1.5], 2.0) == (1.0, None, 1.0)
    # an oscillating sequence has no observed order; order 1 is used
    assert richardson([1.0, 2.0, 1.5], 2.0)[1:] == (None, 1.0)


def _grid(limit=10.0, cs=0.8, ct=0.05, levels=(0, 1, 2, 3), p=1.0, nstep=3):
    """Runs of x = limit + cs h^p + ct dt / dt0, h = 2^(-K/2), dt0 = 1e-3 2^(-K/2); their cost
    as points x steps."""
    runs = []
    for k in levels:
        h = 2 ** (-k / 2)
        for j in range(nstep):
            dt = 1e-3 * h / 2**j
            runs.append(
                {
                    "level": k,
                    "nvert": 80 * 2**k,
                    "dt": dt,
                    "status": "ok",
                    "values": {"m": limit + cs * h**p + ct * dt / 1e-3},
                    "cpu_s_per_sim_s": 80 * 2**k / dt * 1e-6,
                }
            )
    return runs


def test_estimate_separates_space_and_time_and_recommends_the_cheapest_run():
    runs = _grid()
    est = estimate(runs, ("m",), (0, 1, 2, 3))["m"]
    # exact for a law that is linear in h and in dt
    assert est["limit"] == pytest.approx(10.0, rel=1e-9)
    assert est["observed_order_space"] == pytest.approx(1.0, rel=1e-6)
    assert est["observed_order_time"] == pytest.approx(1.0, rel=1e-6)
    assert est["limit_error_estimate"] == pytest.approx(0.0, abs=1e-9)
    rec = recommend(runs, {"m": est}, ("m",))
    assert [r["target_rel_error"] for r in rec] == list(TARGETS)
    for row in rec:
        meet = [r for r in runs if r["rel_error"]["m"] <= row["target_rel_error"]]
        if meet:  # measured: the cheapest run meeting the target
            assert not row["predicted"] and row["basis"] == "measured"
            assert row["cpu_s_per_sim_s"] == min(r["cpu_s_per_sim_s"] for r in meet)
        elif row["basis"] == "extrapolated":  # a finer level than any run, at most two past
            assert row["predicted"] and 3 < row["level"] <= 3 + MAX_EXTRAPOLATED_LEVELS
        else:  # further: refused
            assert row["basis"] == "beyond" and row["level"] is None and row["levels_past_finest"] > 2


def test_the_limits_error_estimate_leaves_the_coarsest_level_out_and_is_none_from_three_fitted_levels():
    """The limit's error estimate is how far the limit moves when the coarsest level, the least
    asymptotic, is left out: large on a law whose coarse level is off its power law, none from
    exactly three levels whose order they fit (they are fitted exactly, and two cannot fit an
    order: any figure there would be made up)."""
    three = estimate(_grid(levels=(0, 1, 2), p=2.0), ("m",), (0, 1, 2))["m"]
    assert three["observed_order_space"] == pytest.approx(2.0, abs=1e-9)
    assert three["limit"] == pytest.approx(10.0, rel=1e-9) and three["limit_error_estimate"] is None
    assert "| m | 10 | - |" in markdown(
        {
            "scene": "manufactured",
            "levels": [0, 1, 2],
            "steps_per_level": 3,
            "duration_s": 1.0,
            "overrides": [],
            "metrics": ["m"],
            "estimate": {"m": three},
            "finest_change": {},
            "runs": [],
            "recommendation": [],
            "failures": [],
        }
    )
    # four levels on the law: the three finer ones give the same limit, an estimate of round-off
    four = estimate(_grid(levels=(0, 1, 2, 3), p=2.0), ("m",), (0, 1, 2, 3))["m"]
    assert four["limit_error_estimate"] == pytest.approx(0.0, abs=1e-9)
    # the coarsest level 5% of the limit off the law: the limit over all four moves (0.094, its
    # fitted order 3.87) and the estimate is at least that move; leaving the finest level out at
    # the fitted order, which fits the coarse level's error again, gave 0.015
    runs = _grid(levels=(0, 1, 2, 3), p=2.0)
    for r in runs:
        if r["level"] == 0:
            r["values"]["m"] += 0.5
    off = estimate(runs, ("m",), (0, 1, 2, 3))["m"]
    assert abs(off["limit"] - 10.0) > 1e-3
    assert off["limit_error_estimate"] >= abs(off["limit"] - 10.0) * (1 - 1e-6)
    # three levels whose order is not fitted (an oscillation): the formal order 1, whose limit
    # the two finer levels fit again, gives an estimate
    runs = _grid(levels=(0, 1, 2), p=1.0)
    for r in runs:
        if r["level"] == 1:
            r["values"]["m"] -= 1.0
    osc = estimate(runs, ("m",), (0, 1, 2))["m"]
    assert osc["observed_order_space"] is None and osc["limit_error_estimate"] > 0


def check_known_answer(res, limit, p, q, ratio):
    """What `write` computed from runs of x = limit + cs h^p + ct dt (h = ratio^-K):
    the limit, the orders in space and time, and errors that fall by ratio^p a level."""
    e = res["estimate"]["m"]
    # exact up to round-off: time's Richardson is exact for a law linear in dt, and the
    # space fit's order grid holds p (FIT_ORDERS, 0.01 apart)
    assert e["limit"] == pytest.approx(limit, rel=1e-9)
    assert e["observed_order_time"] == pytest.approx(q, rel=1e-9)
    assert e["observed_order_space"] == pytest.approx(p, abs=1e-9)
    errs = e["error_by_level"]
    assert all(a / b == pytest.approx(ratio**p, rel=1e-6) for a, b in zip(errs, errs[1:])), errs
    for r in res["runs"]:  # each run's error against the limit: the law's own
        assert r["rel_error"]["m"] == pytest.approx(abs(r["values"]["m"] - limit) / limit, rel=1e-6, abs=1e-12)


def test_the_study_recovers_a_known_limit_and_orders(tmp_path, monkeypatch):
    """A manufactured study, second order in space and first in time, through the study's
    own `write` (estimate, recommendation, markdown, figure); and the same check fails on a
    study that takes its spacing or its steps for other than they are."""
    from hybrid.studies import convergence

    levels = (0, 1, 2, 3, 4, 5)
    res = {
        "scene": "manufactured",
        "overrides": [],
        "metrics": ["m"],
        "duration_s": 1.0,
        "spacing_ratio": RATIO_SPACE,
        "levels": list(levels),
        "steps_per_level": 3,
        "runs": _grid(levels=levels, p=2.0),
        "failures": [],
    }
    out = convergence.write(tmp_path, copy.deepcopy(res))
    check_known_answer(out, 10.0, 2.0, 1.0, RATIO_SPACE)
    assert "| m | 10 |" in (tmp_path / "convergence.md").read_text()
    # broken: the spacing read as halving a level (a file mesh's) instead of sqrt(2)
    with pytest.raises(AssertionError):
        check_known_answer(convergence.write(tmp_path, {**copy.deepcopy(res), "spacing_ratio": 2.0}), 10, 2, 1, 2.0)
    # broken: the steps taken as shrinking by 1.5 a time instead of halving
    monkeypatch.setattr(convergence, "RATIO_TIME", 1.5)
    with pytest.raises(AssertionError):
        check_known_answer(convergence.write(tmp_path, copy.deepcopy(res)), 10.0, 2.0, 1.0, RATIO_SPACE)


def test_the_recommendation_marks_levels_past_the_finest_run_and_refuses_beyond_two():
    """A target the grid does not meet: a level one or two past the finest run is
    "extrapolated" (its cost scaled as points x steps); three or more past it is refused."""
    # levels 0-3, first order in space (the error falls by sqrt(2) a level); a time error
    # large enough that no run meets a target one level away
    runs = _grid(ct=5.0)
    est = estimate(runs, ("m",), (0, 1, 2, 3))
    err_last = est["m"]["error_by_level"][-1]
    # half the target goes to space: a target needing exactly n more levels
    targets = [2 * err_last / RATIO_SPACE**n * (1 + 1e-9) for n in (1, 2, 3)]
    rows = recommend(runs, est, ("m",), targets=targets)
    assert [r["levels_past_finest"] for r in rows] == [1, 2, 3]
    assert [r["basis"] for r in rows] == ["extrapolated", "extrapolated", "beyond"]
    finest = max(runs, key=lambda r: (r["nvert"], -r["dt"]))
    for n, r in zip((1, 2), rows):
        assert r["predicted"] and r["level"] == 3 + n and r["nvert"] == finest["nvert"] * 2**n
        assert r["cpu_s_per_sim_s"] == pytest.approx(
            finest["cpu_s_per_sim_s"] * r["nvert"] / finest["nvert"] * finest["dt"] / r["dt"], rel=1e-12
        )
    assert rows[2]["level"] is None and rows[2]["cpu_s_per_sim_s"] is None
    text = markdown(
        {
            "scene": "manufactured",
            "levels": [0, 1, 2, 3],
            "steps_per_level": 3,
            "duration_s": 1.0,
            "overrides": [],
            "metrics": ["m"],
            "estimate": est,
            "finest_change": {},
            "runs": runs,
            "recommendation": rows,
            "failures": [],
        }
    )
    assert "| 4 | 160 |" not in text  # levels are not points: a sanity check of the rows below
    assert text.count("| measured |") == 0
    assert "extrapolated, 1 level past the finest run" in text and "extrapolated, 2 levels past" in text
    assert "| > 5 |" in text and "asks 3 levels past the finest run" in text


#: symplectic Euler is first order; the next term of its error moves the order observed over
#: three steps by a share of the step, 0.001-0.011 at 1 to 0.125 ms on this scene's series
#: (`hybrid study work-precision`: local orders 1.001-1.011); the maxima over frames, not smooth
#: in dt, may add a little: 0.05 (measured 0.999-1.005)
ORDER_TIME_WINDOW = 0.05


def test_small_convergence_study_of_the_breathing_scene(tmp_path, capsys):
    assert main_study(["convergence", "--out", str(tmp_path), "--small", "--steps", "3"]) == 0
    assert "convergence:" in capsys.readouterr().out
    data = strict_load(tmp_path / "convergence.json")
    body_metrics = [k for k in DEFAULT_METRICS if k not in LUNG_METRICS]  # the scene has no lungs
    assert data["scene"] == "breathing" and data["metrics"] == body_metrics
    assert len(data["runs"]) == 3 * 3 and not data["failures"]
    for r in data["runs"]:
        assert set(r) >= {"level", "nvert", "dt", "values", "wall_s", "cpu_s", "cpu_s_spread", "repeats"}
        assert all(math.isfinite(v) for v in r["values"].values())
    # each level about doubles the points; each level's steps halve
    nv = sorted({r["nvert"] for r in data["runs"]})
    assert nv[0] == 80 and all(1.6 < b / a < 2.4 for a, b in zip(nv, nv[1:]))
    for k in body_metrics:
        e = data["estimate"][k]
        assert abs(e["observed_order_time"] - 1.0) <= ORDER_TIME_WINDOW, (k, e["observed_order_time"])
        for level in data["levels"]:  # each level's values converge in time: the changes shrink
            xs = [r["values"][k] for r in sorted(data["runs"], key=lambda r: -r["dt"]) if r["level"] == level]
            assert abs(xs[0] - xs[1]) > abs(xs[1] - xs[2]) > 0, (k, level, xs)
    # the costs are measured (CPU time per simulated second, positive, repeated): their growth with
    # the points and the steps is checked by the command on a busy machine, not here (no timed
    # assertion: a clean-clone run once found level 1 no dearer than level 0 at these sizes)
    assert all(r["cpu_s_per_sim_s"] > 0 and r["repeats"] >= 1 for r in data["runs"])
    by = {(r["level"], r["dt"]) for r in data["runs"]}
    rows = data["recommendation"]
    assert {(r["metric"], r["target_rel_error"]) for r in rows} == {(k, t) for k in body_metrics for t in TARGETS}
    for r in rows:
        if r["basis"] == "measured":
            assert (r["level"], r["dt"]) in by
        elif r["basis"] == "beyond":
            assert r["level"] is None and r["levels_past_finest"] > MAX_EXTRAPOLATED_LEVELS
        else:
            assert 0 <= r["level"] - 2 == r["levels_past_finest"] <= MAX_EXTRAPOLATED_LEVELS
    md = (tmp_path / "convergence.md").read_text()
    assert md.startswith("# Convergence") and md.count("| measured |") == sum(r["basis"] == "measured" for r in rows)
    assert (tmp_path / "convergence.png").stat().st_size > 10_000


def test_small_convergence_study_of_the_breathing_trunk_with_lungs_takes_the_lung_metrics(tmp_path, capsys):
    """The study on breathing_lungs: the lung metrics (the lung volume, Pdi, the lowest pleural
    pressure, the walls' sweeps) besides the body's, each level's values converging in time (first
    order: the changes halve with the step)."""
    args = ["convergence", "breathing_lungs", "--out", str(tmp_path), "--small", "--steps", "3", "--repeats", "1"]
    assert main_study(args) == 0
    data = strict_load(tmp_path / "convergence.json")
    assert data["metrics"] == list(DEFAULT_METRICS) and not data["failures"]
    for k in LUNG_METRICS:
        assert abs(data["estimate"][k]["observed_order_time"] - 1.0) <= ORDER_TIME_WINDOW, k
        for level in data["levels"]:
            xs = [r["values"][k] for r in sorted(data["runs"], key=lambda r: -r["dt"]) if r["level"] == level]
            assert xs[0] != 0 and abs(xs[0] - xs[1]) > abs(xs[1] - xs[2]) > 0, (k, level, xs)


def test_convergence_refuses_an_unknown_metric_in_one_line(tmp_path, capsys):
    code = main_study(
        [
            "convergence",
            "--out",
            str(tmp_path),
            "--small",
            "--metric",
            "snore_mm",
            "--levels",
            "0-1",
            "--steps",
            "1",
            "--duration",
            "0.01",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "snore_mm" in err and "apex_descent_mm" in err


def test_the_work_of_breathing_is_a_metric_over_whole_breaths(tmp_path, capsys):
    """`--metric work_of_breathing_j_per_l`: the run summary's work per litre inspired, each run's
    own (a run from rest over one breath holds one inspiration); a run too short to hold one is
    refused in one line, not studied as a missing value."""
    from hybrid.model import compile_scene
    from hybrid.resolve import resolve_scene
    from hybrid.run import run as run_scene
    from hybrid.simulation import Simulation

    sets = ["--integrator", "implicit_euler", "--set", "dt_s=0.02", "--repeats", "1"]
    metric = ["--metric", "work_of_breathing_j_per_l", "--metric", "lung_volume_change_l"]
    args = ["convergence", "breathing_lungs", "--levels", "0-1", "--steps", "2", "--duration", "4", *sets, *metric]
    assert main_study([*args, "--out", str(tmp_path / "whole")]) == 0
    data = strict_load(tmp_path / "whole" / "convergence.json")
    assert data["metrics"] == ["work_of_breathing_j_per_l", "lung_volume_change_l"] and not data["failures"]
    run0 = next(r for r in data["runs"] if r["level"] == 0 and r["dt"] == 0.02)
    model = compile_scene(
        resolve_scene("breathing_lungs", overrides=["integrator=implicit_euler", "dt_s=0.02", "mesh.level=0"])
    )
    own = run_scene(Simulation(model), 4.0)["summary"]["work_of_breathing_j_per_l"]
    assert own > 0 and run0["values"]["work_of_breathing_j_per_l"] == own
    short = ["convergence", "breathing_lungs", "--small", "--repeats", "1", "--metric", "work_of_breathing_j_per_l"]
    assert main_study([*short, "--out", str(tmp_path / "short")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "complete inspiration" in err and "--duration" in err


def test_a_metric_may_take_its_series_smallest_value(tmp_path, capsys):
    """NAME:min studies the series' smallest value (a pressure that falls), the run's own minimum;
    another statistic is refused in one line."""
    from hybrid.model import compile_scene
    from hybrid.resolve import resolve_scene
    from hybrid.run import run as run_scene
    from hybrid.simulation import Simulation
    from hybrid.studies.convergence import simulate

    name = "pleural_pressure_cmh2o"
    res = simulate("breathing_lungs", [], 0, None, 0.3, (name, f"{name}:min"), repeats=1)
    table = run_scene(Simulation(compile_scene(resolve_scene("breathing_lungs", overrides=["mesh.level=0"]))), 0.3)[
        "summary"
    ]["metrics"][name]
    assert res["values"] == {name: table["max"], f"{name}:min": table["min"]}
    assert table["min"] < table["max"] < 0.0  # it fell with the inspiration, below the atmosphere's
    code = main_study(
        ["convergence", "breathing_lungs", "--out", str(tmp_path / "x"), "--small", "--metric", f"{name}:median"]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "NAME:min" in err and "median" in err


def test_a_mesh_read_from_a_file_refines_by_splitting_its_faces(tmp_path, capsys):
    """The study's levels on a file mesh: faces split into four a level, the spacing halved."""
    from hybrid.model import compile_scene
    from hybrid.resolve import resolve_scene

    path = tmp_path / "level0.obj"
    compile_scene(resolve_scene("breathing", overrides=["mesh.level=0"])).mesh.save(path)
    out = tmp_path / "cv"
    assert (
        main_study(
            [
                "convergence",
                "--out",
                str(out),
                "--small",
                "--steps",
                "1",
                "--duration",
                "0.1",
                "--set",
                f"mesh.path={path}",
            ]
        )
        == 0
    )
    data = strict_load(out / "convergence.json")
    assert data["spacing_ratio"] == 2.0 and data["levels"] == [0, 1] and not data["failures"]
    nv = [r["nvert"] for r in data["runs"]]
    assert nv == [80, 80 + 3 * 156 // 2]  # a closed surface: one new point per edge, E = 3F/2
    assert all(math.isfinite(v) for r in data["runs"] for v in r["values"].values())


def test_convergence_with_implicit_euler_steps_from_its_own_step(tmp_path):
    """`--integrator implicit_euler`: each level's steps halve from implicit Euler's own
    "auto" step (4x symplectic Euler's), not from the explicit bound."""
    from hybrid.studies.convergence import base_step

    assert (
        main_study(
            [
                "convergence",
                "--out",
                str(tmp_path),
                "--integrator",
                "implicit_euler",
                "--levels",
                "0-1",
                "--steps",
                "2",
                "--duration",
                "0.2",
                "--repeats",
                "1",  # the steps are checked here, not the costs
            ]
        )
        == 0
    )
    data = strict_load(tmp_path / "convergence.json")
    assert data["overrides"] == ["integrator=implicit_euler"] and not data["failures"]
    for level in (0, 1):
        dt0, _ = base_step("breathing", ("integrator=implicit_euler",), level)
        explicit, _ = base_step("breathing", (), level)
        assert dt0 >= 2 * explicit
        assert sorted(r["dt"] for r in data["runs"] if r["level"] == level) == [dt0 / 2, dt0]


@pytest.mark.skipif(importlib.util.find_spec("myo_sim") is None, reason="myo_sim (pip install -e '.[myo]') absent")
def test_small_convergence_study_of_the_fitted_torso(tmp_path):
    """`hybrid study convergence myotorso_breathing` (a trunk fitted to a model, on its own mesh):
    the fitted membrane read from its file refines a level (4 times the points, its regions carried,
    the lungs and the sliding zone with it) under implicit Euler from the scene's own 2 ms. Measured
    over 0.5 s: the metrics change by 0.95-3.3% from level 0 to 1; a region lost in the refinement
    (the dome, the zone) moves them by far more than the 10% allowed."""
    args = ["convergence", "myotorso_breathing", "--out", str(tmp_path), "--small", "--repeats", "1"]
    assert main_study(args) == 0
    data = strict_load(tmp_path / "convergence.json")
    assert not data["failures"] and data["levels"] == [0, 1] and set(LUNG_METRICS) <= set(data["metrics"])
    points = {r["level"]: r["nvert"] for r in data["runs"]}
    assert points[1] > 3.9 * points[0]
    # the walls' sweeps (the compartments' volume changes) over 0.5 s from rest are small on this
    # coarse mesh and move by 6-80% from level 0 to 1 (measured; the abdominal rib cage's the most):
    # they are in the study, but not in this check (finer levels: docs/anatomy.md)
    walls = {"rib_cage_pulmonary_volume_change_l", "rib_cage_abdominal_volume_change_l", "abdomen_volume_change_l"}
    for k in data["metrics"]:
        if k not in walls:
            assert 0 < data["finest_change"][k] <= 0.10, (k, data["finest_change"][k])
