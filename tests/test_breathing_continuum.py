"""The packaged breathing scene in the continuum formulation, at its default mesh level:
quiet breathing in the physiological ranges, the volume exact, back at rest after the
breath, and the paper's mechanism (without the volume constraint the ribs barely rise).
Its convergence under refinement is `hybrid study convergence`'s (tests/studies)."""

from __future__ import annotations

import pytest

import hybrid
from hybrid.run import run

PERIOD_S = 4.0


@pytest.fixture(scope="module")
def one_breath():
    return run(hybrid.load("breathing"), PERIOD_S)["summary"]


def test_quiet_breathing_in_the_physiological_ranges(one_breath):
    s = one_breath
    assert s["provenance"]["dt_s"] > 0 and s["status"] == "ok"
    # diaphragm excursion 18 +/- 3 mm (acceptance 10-25), lower chest wall 3-5 mm (2-8),
    # a swing of a few cmH2O in the abdomen (100-600 Pa)
    assert 10.0 <= s["apex_descent_mm"] <= 25.0, s["apex_descent_mm"]
    assert 2.0 <= s["rib_lift_mm"] <= 8.0, s["rib_lift_mm"]
    assert 100.0 <= s["pressure_max_pa"] <= 600.0, s["pressure_max_pa"]
    assert s["volume_rel_error_max"] <= 1e-12
    # the dome displaces 100-400 mL into the abdomen (tidal volume about 0.5 L, of which
    # the diaphragm moves 0.6-0.75)
    assert 100.0 <= s["metrics"]["swept_volume_ml"]["max"] <= 400.0
    # back at rest at the end of the breath: within 5% of the descent (the slowest mode
    # decays over a breath, not within one step)
    assert s["rest_return_mm"] is not None and s["rest_return_mm"] < 0.05 * s["apex_descent_mm"]


def test_without_the_volume_constraint_the_ribs_rise_at_most_a_third(one_breath):
    without = run(hybrid.load("breathing", without=["volume"]), 2.0)["summary"]
    assert without["rib_lift_mm"] <= one_breath["rib_lift_mm"] / 3.0, (
        without["rib_lift_mm"],
        one_breath["rib_lift_mm"],
    )
    assert without["volume_rel_change_max"] > 0.01  # the abdomen gives way instead
