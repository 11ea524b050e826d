"""The stability study (paper 6.1) at its small size: the JSON, Table 1's check, no NaN."""

from __future__ import annotations

from helpers import strict_load

from hybrid.studies.cli import main_study


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
        assert isinstance(r["h_max"], (int, float)) and r["h_max"] >= 0
        assert r["iterations"] is None or isinstance(r["iterations"], int)
    # Table 2 from the eigenvalues: the closed forms, e.g. shape memory's kv/h
    for row in data["table2"]["k_max_by_h"]:
        for model in ("mass_spring", "shape_memory"):
            got = row[model]
            assert abs(got["k_max_eigenvalues"] - got["k_max_closed_form"]) <= 1e-9 * got["k_max_closed_form"]
    assert (tmp_path / "stability.md").is_file()
    for png in data["plots"]:
        assert (tmp_path / png).stat().st_size > 0
