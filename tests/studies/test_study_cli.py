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


def test_a_folder_with_the_study_s_earlier_output_is_refused_unless_overwrite(tmp_path, capsys):
    earlier = tmp_path / "rigid.json"
    earlier.write_text('{"earlier": true}')
    md = tmp_path / "rigid.md"
    assert main_study(["rigid", "breathing", "--small", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "rigid.json" in err and "--overwrite" in err and str(tmp_path) in err
    assert earlier.read_text() == '{"earlier": true}' and not md.exists()  # nothing written, nothing replaced
    assert main_study(["rigid", "breathing", "--small", "--out", str(tmp_path), "--overwrite"]) == 0
    assert '"earlier"' not in earlier.read_text() and md.exists()
