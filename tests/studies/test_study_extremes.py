"""The extremes catalogue at its small size: every case ends stable, diverged or
refused, with a message; no NaN in the JSON; nothing unexpected raised."""

from __future__ import annotations

from helpers import strict_load

from hybrid.studies.cli import main_study


def test_small_extremes_catalogue(tmp_path, capsys, monkeypatch):
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    assert main_study(["extremes", "--out", str(tmp_path), "--small"]) == 0
    assert "extremes:" in capsys.readouterr().out
    assert not list(cwd.iterdir())  # MuJoCo's warnings (light ribs) leave no MUJOCO_LOG.TXT here
    data = strict_load(tmp_path / "extremes.json")
    cases = data["cases"]
    assert len(cases) >= 14
    names = [c["name"] for c in cases]
    assert len(set(names)) == len(names)
    for c in cases:
        assert set(c) >= {"name", "outcome", "message", "volume_rel_error_max"}
        assert c["outcome"] in ("stable", "diverged", "refused"), c
        assert isinstance(c["message"], str) and c["message"], c
        assert not c["message"].startswith("BUG"), c
        v = c["volume_rel_error_max"]
        if c["outcome"] == "stable":
            assert isinstance(v, float) and 0.0 <= v < 1e-6, c  # the exact projection
        if c["outcome"] == "refused":
            assert v is None
        if c["outcome"] == "diverged":
            assert isinstance(c["step"], int)
    assert data["bugs"] == []
    by = {c["name"]: c["outcome"] for c in cases}
    assert by["baseline_membrane"] == "stable" and by["baseline_coupled"] == "stable"
    assert by["invalid_dt"] == "refused" and by["missing_mjcf"] == "refused"
    assert by["dt_2x_bound"] == "diverged"
    # implicit Euler at each stiff case's own step: refused in the paper formulation;
    # the continuum equivalents that diverge with symplectic Euler are stable with it,
    # the volume exact
    assert by["shape_memory_x100/implicit_euler"] == "refused" and by["mesh_40962/implicit_euler"] == "refused"
    assert by["continuum_baseline"] == "stable"
    rows = {c["name"]: c for c in cases}
    for name in ("continuum_membrane_x100", "continuum_mesh_40962", "continuum_dt_2x_bound"):
        assert by[name] == "diverged", name
        imp = rows[f"{name}/implicit_euler"]
        assert imp["outcome"] == "stable" and imp["volume_rel_error_max"] <= 1e-12, imp
        assert imp["dt_s"] == rows[name]["dt_s"]
    assert rows["continuum_dt_at_bound/implicit_euler"]["outcome"] == "stable"
    assert rows["continuum_muscle_x100/implicit_euler"]["outcome"] == "stable"
    # an obstructed airway (20 cmH2O s/L) under implicit Euler at 20 ms: a case a respiratory
    # researcher runs; until 0.17 its solve stopped at 1.94 s, the lungs' load on the ribs a step
    # late (`hybrid.wall_coupling`)
    lungs = rows["lungs_obstructed_implicit"]
    assert lungs["reasonable"] and lungs["outcome"] == "stable", lungs
    assert lungs["volume_rel_error_max"] <= 1e-12, lungs
