"""`hybrid study convergence`: Richardson extrapolation recovers closed-form limits and
orders, and the small study runs the breathing scene on a grid of levels x steps."""

from __future__ import annotations

import math

import pytest
from helpers import strict_load

from hybrid.studies.cli import main_study
from hybrid.studies.convergence import DEFAULT_METRICS, TARGETS, estimate, recommend, richardson


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


def _grid(limit=10.0, cs=0.8, ct=0.05, levels=(0, 1, 2, 3)):
    """Runs of x = limit + cs h + ct dt, h = 2^(-K/2), dt0 = 1e-3 2^(-K/2)."""
    runs = []
    for k in levels:
        h = 2 ** (-k / 2)
        for j in range(3):
            dt = 1e-3 * h / 2**j
            runs.append(
                {
                    "level": k,
                    "nvert": 80 * 2**k,
                    "dt": dt,
                    "status": "ok",
                    "values": {"m": limit + cs * h + ct * dt / 1e-3},
                    "wall_s_per_sim_s": 80 * 2**k / dt * 1e-6,
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
            assert not row["predicted"]
            assert row["wall_s_per_sim_s"] == min(r["wall_s_per_sim_s"] for r in meet)
        else:  # predicted beyond the grid: a finer level than any run
            assert row["predicted"] and row["level"] > 3


def test_small_convergence_study_of_the_breathing_scene(tmp_path, capsys):
    assert main_study(["convergence", "--out", str(tmp_path), "--small"]) == 0
    assert "convergence:" in capsys.readouterr().out
    data = strict_load(tmp_path / "convergence.json")
    assert data["scene"] == "breathing" and data["metrics"] == list(DEFAULT_METRICS)
    assert len(data["runs"]) == 3 * 2 and not data["failures"]
    for r in data["runs"]:
        assert set(r) >= {"level", "nvert", "dt", "values", "wall_s", "wall_s_per_sim_s"}
        assert all(math.isfinite(v) for v in r["values"].values())
    # each level about doubles the points; each level's steps halve
    nv = sorted({r["nvert"] for r in data["runs"]})
    assert nv[0] == 80 and all(1.6 < b / a < 2.4 for a, b in zip(nv, nv[1:]))
    for k in DEFAULT_METRICS:
        e = data["estimate"][k]
        assert set(e) >= {"limit", "observed_order_space", "observed_order_time", "error_by_level"}
        assert len(e["error_by_level"]) == 3
    rows = data["recommendation"]
    assert {(r["metric"], r["target_rel_error"]) for r in rows} == {(k, t) for k in DEFAULT_METRICS for t in TARGETS}
    assert (tmp_path / "convergence.md").read_text().startswith("# Convergence")
    assert (tmp_path / "convergence.png").stat().st_size > 10_000


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
