"""hybrid study work-precision: a small version through the command line."""

import json
import math

from hybrid.studies.cli import main_study
from hybrid.studies.work_precision import observed_order


def test_small_work_precision(tmp_path, capsys):
    assert main_study(["work-precision", "--out", str(tmp_path), "--small"]) == 0
    assert "observed order" in capsys.readouterr().out
    text = (tmp_path / "work_precision.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    d = json.loads(text)
    assert (tmp_path / "work_precision.png").stat().st_size > 0 and (tmp_path / "work_precision.md").exists()
    assert d["failures"] == []
    keys = {f"{s}/{i}" for s in ("breathing", "membrane") for i in ("explicit_euler", "symplectic_euler")}
    assert set(d["order"]) == keys
    for r in d["runs"]:
        assert {"scene", "integrator", "dt", "error", "wall_s"} <= set(r)
        assert all(isinstance(r[k], float) and math.isfinite(r[k]) and r[k] > 0 for k in ("dt", "error", "wall_s"))
        assert r["pressure_error"] >= 0 and (r["angle_error"] is None) == (r["scene"] == "membrane")
        assert (r["rib_lift_error_mm"] is None) == (r["scene"] == "membrane")
        assert abs(0.01 / r["dt"] - round(0.01 / r["dt"])) < 1e-9
    # the references are converged: Richardson's estimate of their error is far below every run's
    for s, ref in d["reference"].items():
        assert ref["converged"] and ref["error_estimate"] < 0.1 * ref["smallest_run_error"], s
    sym = sorted(
        (r for r in d["runs"] if r["scene"] == "membrane" and r["integrator"] == "symplectic_euler"),
        key=lambda r: -r["dt"],
    )
    assert len(sym) >= 4
    assert all(a["error"] > b["error"] for a, b in zip(sym, sym[1:]))  # errors decrease with h
    # First order for both Euler variants: explicit and symplectic Euler are each
    # first-order one-step methods (local error O(h^2), global O(h)), and the volume
    # projection after the step does not raise that: it is a first-order
    # (position-based) projection whose velocity correction is (x_proj - x)/h, so
    # the constrained scheme stays O(h); the muscle schedules are sampled at the
    # step's start (O(h) too). So error ~ C h: slope 1 on the log-log plot.
    for key, p in d["order"].items():
        assert 0.7 < p < 1.5, (key, p)
    assert abs(observed_order([1.0, 0.5, 0.25], [4.0, 2.0, 1.0]) - 1.0) < 1e-12
    # the rib lift's error falls with the step too (first order: halving h about halves it)
    lift = sorted(
        (r for r in d["runs"] if r["scene"] == "breathing" and r["integrator"] == "symplectic_euler"),
        key=lambda r: -r["dt"],
    )
    assert all(a["rib_lift_error_mm"] > b["rib_lift_error_mm"] for a, b in zip(lift, lift[1:]))
    assert "hybrid study convergence" in (tmp_path / "work_precision.md").read_text()


def test_small_work_precision_on_dask_cluster(tmp_path, dask_cluster):
    """`--scheduler ADDRESS` sends the runs to an existing Dask cluster."""
    assert (
        main_study(["work-precision", "--out", str(tmp_path), "--small", "--scheduler", dask_cluster.scheduler_address])
        == 0
    )
    d = json.loads((tmp_path / "work_precision.json").read_text())
    assert d["scheduler"] == dask_cluster.scheduler_address and d["failures"] == []
    assert len(d["runs"]) == 16 and all(0.7 < p < 1.5 for p in d["order"].values())
