"""The stability study (paper 6.1) at its small size: the JSON, Table 1's check, Table 3's
figures as the README states them, no NaN."""

from __future__ import annotations

import copy

import pytest
from helpers import strict_load

from hybrid.studies.cli import main_study
from hybrid.studies.stability.tables import KV_UNIT, M_UNIT

#: Table 3 as the README states it: the largest h reaching equilibrium, the least over 10 seeds
README_TABLE3 = {
    ("mass_spring", 0.3): 3.63,
    ("mass_spring", 0.7): 2.55,
    ("shape_memory", 0.3): 4.00,
    ("shape_memory", 0.7): 4.00,
}
#: the README's rounding of those figures (two decimals)
README_HALF_ULP = 0.005
#: how close the study brackets each seed's largest h: its grid's spacing 0.1 halved 7 times
BRACKET = 0.1 / 2**7


def check_table3(rows) -> None:
    """Table 3's rows hold the README's figures and their bisection brackets."""
    assert {(r["model"], r["perturbation"]) for r in rows} == set(README_TABLE3)
    for r in rows:
        key = (r["model"], r["perturbation"])
        # the least over the seeds, to the README's two decimals (each seed's own h_max is
        # known to BRACKET, far finer than that rounding)
        assert abs(r["h_max"] - README_TABLE3[key]) <= README_HALF_ULP, (key, r["h_max"])
        assert r["h_max"] == min(s["h_max"] for s in r["seeds"]) and len(r["seeds"]) == 10, key
        for s in r["seeds"]:  # each seed's h_max: a success BRACKET below a failure
            assert 0 < s["first_failure_h"] - s["h_max"] <= BRACKET * (1 + 1e-9), (key, s)
        if r["model"] == "shape_memory":
            # a known answer: shape memory is bounded by the damping of the free rigid motions,
            # h < 2m/kv, whatever the perturbation; the bracket must hold it
            assert min(s["h_max"] for s in r["seeds"]) <= 2 * M_UNIT / KV_UNIT
            assert all(s["first_failure_h"] > 2 * M_UNIT / KV_UNIT for s in r["seeds"]), key


def test_small_stability_study_writes_the_json(tmp_path):
    assert main_study(["stability", "--out", str(tmp_path), "--small"]) == 0
    data = strict_load(tmp_path / "stability.json")
    assert data["table1_max_abs_error"] <= 1e-12
    rows = data["table3"]
    assert {(r["model"], r["perturbation"]) for r in rows} == {
        (m, p) for m in ("mass_spring", "shape_memory") for p in (0.3, 0.7)
    }
    for r in rows:
        assert set(r) >= {"model", "perturbation", "h_max", "iterations"}
        assert r["iterations"] is None or isinstance(r["iterations"], int)
    check_table3(rows)
    # the check has teeth: a study whose bound moved by a grid step, or whose bisection
    # stopped early, fails it
    for broken in ("moved", "coarse"):
        bad = copy.deepcopy(rows)
        if broken == "moved":
            bad[1]["h_max"] -= 0.1
            bad[1]["seeds"][0]["h_max"] = bad[1]["h_max"]
        else:
            for s in bad[0]["seeds"]:
                s["h_max"] -= 2 * BRACKET
        with pytest.raises(AssertionError):
            check_table3(bad)
    # Table 2 from the eigenvalues: the closed forms, e.g. shape memory's kv/h
    for row in data["table2"]["k_max_by_h"]:
        for model in ("mass_spring", "shape_memory"):
            got = row[model]
            assert abs(got["k_max_eigenvalues"] - got["k_max_closed_form"]) <= 1e-9 * got["k_max_closed_form"]
    assert (tmp_path / "stability.md").is_file()
    for png in data["plots"]:
        assert (tmp_path / png).stat().st_size > 0
