"""`hybrid study verification --small`: the continuum formulation's oracles hold at the
small study's resolutions (the full study, with finer meshes, is the command's)."""

from __future__ import annotations

import copy

import pytest
from helpers import strict_load

from hybrid.studies.cli import main_study

#: the full study's hanging balloons: their spread across the families at their finest
#: level (README: "agree within 1.29% of their mean"), and each family's points there
FULL_SPREAD = 0.0129
FULL_POINTS = {"uv": 2522, "icosphere": 2562, "irregular": 2562}


def check_hanging_spread(data) -> None:
    """The families' hanging balloons agree within their discretisation error.

    The spread is the difference of two families' errors, second order in the spacing (the
    pressure sphere's observed orders, 1.9-2.6) and so inversely proportional to the points: at
    the small study's meshes the full study's 1.29% grows by the ratio of points of the two
    families that set it (measured 2.60% with uv at 1106 points and irregular at 1282, the
    full study's 2522 and 2562: a ratio of 2.28, a bound of 2.94%)."""
    finest = data["hanging_finest"]
    sag = {fam: v["sag_m"] for fam, v in finest.items()}
    mean = sum(sag.values()) / len(sag)
    spread = (max(sag.values()) - min(sag.values())) / mean
    assert spread == pytest.approx(data["hanging_finest_spread"], rel=1e-12)
    extremes = (min(sag, key=sag.get), max(sag, key=sag.get))
    bound = FULL_SPREAD * max(FULL_POINTS[f] / finest[f]["nvert"] for f in extremes)
    assert spread <= bound, (spread, bound, finest)


def test_small_verification_study(tmp_path, capsys):
    assert main_study(["verification", "--out", str(tmp_path), "--small"]) == 0
    assert "verification:" in capsys.readouterr().out
    assert (tmp_path / "verification.md").read_text().startswith("# Verification")
    assert (tmp_path / "verification.png").stat().st_size > 10_000
    data = strict_load(tmp_path / "verification.json")
    rows = data["rows"]
    for r in rows:
        assert set(r) >= {"oracle", "mesh_family", "nvert", "measured", "predicted", "rel_error"}
        assert r.get("settled", True), r  # every relaxation reached its equilibrium
    by = {}
    for r in rows:
        by.setdefault(r["oracle"], []).append(r)
    # the pressurised sphere: second order on every family (a linear element's error in the
    # geometry, O(h^2)), within 1% of the closed form at each family's finest small level
    # (about 600-1300 points); the errors fall monotonically with the level
    for fam in ("uv", "icosphere", "irregular"):
        fr = [r for r in by["pressure_sphere"] if r["mesh_family"] == fam]
        assert len(fr) >= 3
        assert fr[-1]["rel_error"] < 0.01, fr[-1]
        assert all(a["rel_error"] > b["rel_error"] for a, b in zip(fr, fr[1:])), fr
        assert data["order"][fam] > 1.5, data["order"]
    # the hanging balloon on three families at about 600-1300 points: they agree within
    # the discretisation error expected there (check_hanging_spread); a study whose one
    # family hangs 1% lower fails it, as 5% did not
    check_hanging_spread(data)
    bad = copy.deepcopy(data)
    fam = max(bad["hanging_finest"], key=lambda f: bad["hanging_finest"][f]["sag_m"])
    bad["hanging_finest"][fam]["sag_m"] *= 1.01
    sags = [v["sag_m"] for v in bad["hanging_finest"].values()]
    bad["hanging_finest_spread"] = (max(sags) - min(sags)) / (sum(sags) / len(sags))
    with pytest.raises(AssertionError):
        check_hanging_spread(bad)
    # exact oracles: round-off only
    assert max(r["measured"] for r in by["patch_test"]) < 1e-12
    for oracle in ("free_body_net_force", "free_body_net_moment", "free_body_momentum", "paper_table1"):
        assert by[oracle][0]["measured"] < 1e-12, by[oracle]
    # SHAKE's projection (the continuum formulation's) is symplectic and its constraint
    # impulse central: the angular momentum is kept to round-off, and the energy of the
    # free, undamped body stays bounded over 10^5 steps (no drift beyond 1e-3 at two steps,
    # against a 15% oscillation of symplectic Euler at the larger one)
    assert by["free_body_angular_momentum"][0]["measured"] < 1e-12, by["free_body_angular_momentum"]
    e = by["free_body_energy"][0]
    assert all(abs(c) < 1e-3 for c in e["change_by_dt"].values()), e
