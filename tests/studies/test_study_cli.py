"""`hybrid study ...` (hybrid.studies.cli): bad input is one line with status 2."""

from __future__ import annotations

import pytest

from hybrid.studies.cli import main_study


def test_study_cli_bad_input_is_one_line_status_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main_study(["extremes"])  # --out missing
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("hybrid study: error:") and err.count("\n") == 1


def test_bad_scheduler_option(capsys):
    with pytest.raises(SystemExit) as info:
        main_study(["work-precision", "--scheduler"])
    assert info.value.code == 2 and "scheduler" in capsys.readouterr().err
