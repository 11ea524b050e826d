"""The benchmark: MuJoCo's flex comparison measures what it says, and every section
gives the figures `hybrid bench --json` writes."""

from hybrid import bench
from hybrid.mesh import uv_sphere


def test_flex_sphere_loses_volume_under_load():
    # MuJoCo's 2D flex has no volume constraint: a soft 4 kg shell resting on a
    # plane flattens, so its enclosed volume drops measurably within 0.3 s
    mesh = uv_sphere(0.12)
    row = bench.flex_sphere_row(mesh, 0.3)
    assert row["nvert"] == 80
    assert row["us_per_step"] > 0
    assert row["volume_change"] < -0.01


def test_bench_sections_keep_their_keys_and_format():
    # each section on a tiny workload: the keys `hybrid bench --json` writes
    result = {
        "membrane": bench.bench_membrane_rows((None,), repeats=1, work=2e3),
        "coupled": bench.coupled_row(nstep=8, repeats=1),
        "recording": bench.recording_row(duration_s=0.05, repeats=1),
        "flex": bench.flex_rows(duration_s=0.01),
    }
    assert {
        "nvert",
        "us_per_step",
        "ns_per_vertex_step",
        "serial_us_per_step",
        "parallel_us_per_step",
        "default_build",
        "default_to_faster",
    } <= set(result["membrane"][0])
    assert result["membrane"][0]["nvert"] == 80
    assert set(result["coupled"]) == {"us_per_step", "mj_step_us", "ratio"}
    assert set(result["recording"]) == {"duration_s", "run_s", "recorded_s", "inline_s", "ratio", "inline_ratio"}
    assert [row["nvert"] for row in result["flex"]] == [80, 642]
    assert {"us_per_step", "volume_change", "ours_volume_change"} <= set(result["flex"][0])
    table = bench.format_table(result)
    assert "coupled" in table and "recording" in table and "flex" in table


def test_implicit_and_realtime_rows_keep_their_keys():
    rows = bench.implicit_rows((None,), repeats=1, work=2e3)
    assert rows[0]["nvert"] == 80
    assert rows[0]["implicit_us_per_step"] > 0 and rows[0]["explicit_us_per_step"] > 0
    assert rows[0]["newton_per_step"] >= 0 and rows[0]["cg_per_step"] >= rows[0]["newton_per_step"]
    rt = bench.realtime_row("breathing", 0, integrator="implicit_euler", dt_s=4e-3, duration_s=0.05, repeats=1)
    assert {"level", "nvert", "integrator", "dt", "wall_s", "sim_s", "realtime_factor"} <= set(rt)
    assert rt["level"] == 0 and rt["nvert"] == 80 and rt["integrator"] == "implicit_euler" and rt["dt"] == 4e-3
    assert rt["realtime_factor"] == rt["sim_s"] / rt["wall_s"]
    table = bench.format_table({"implicit": rows, "realtime": [rt]})
    assert "implicit Euler" in table and "realtime factor" in table


def test_realtime_row_at_a_level_without_a_measured_run_takes_symplectic_euler_below_its_bound():
    rt = bench.realtime_row("breathing", 1, duration_s=0.05, repeats=1)
    assert rt["integrator"] == "symplectic_euler"
    assert abs(0.01 / rt["dt"] - round(0.01 / rt["dt"])) < 1e-9  # divides the 10 ms frame
    model = bench.compile_scene(
        bench.apply_overrides(bench.load_scene(bench.builtin_scene("breathing")), ["mesh.level=1"])
    )
    assert 0.5 * model.dt_stable_s < rt["dt"] <= bench.REALTIME_BOUND_FRACTION * model.dt_stable_s


def test_bench_only_some_sections_and_bad_names_in_one_line(capsys):
    from hybrid.cli import main

    assert main(["bench", "--only", "snore,realtime"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "snore" in err and "realtime" in err
    assert main(["bench", "--realtime-level", "-1"]) == 2
    assert "--realtime-level" in capsys.readouterr().err
    assert set(bench.run_bench(quick=True, only=("realtime",))) == {"realtime"}


def test_the_help_names_every_section():
    # the command line's help is written out (importing the benchmark there would slow every command)
    from hybrid.cli import build_parser

    bench_parser = build_parser()._subparsers._group_actions[0].choices["bench"]
    only = next(a for a in bench_parser._actions if "--only" in a.option_strings)
    assert only.help.split(": ", 1)[1].split(", ") == list(bench.SECTIONS)


def test_the_recommended_levels_realtime_run_is_implicit_euler_solved_to_a_looser_tolerance():
    from hybrid.cli import build_parser

    assert build_parser().parse_args(["bench"]).realtime_level == bench.RECOMMENDED_LEVEL
    integrator, dt, overrides = bench.REALTIME_RUNS[("breathing", bench.RECOMMENDED_LEVEL)]
    frames = dt / 0.01  # a whole number of 10 ms frames a step (a frame at every step), or steps a frame
    assert (
        integrator == "implicit_euler" and min(abs(frames - round(frames)), abs(1 / frames - round(1 / frames))) < 1e-9
    )
    rt = bench.realtime_row(
        "breathing", 1, integrator="implicit_euler", dt_s=dt, overrides=overrides, duration_s=0.1, repeats=1
    )
    assert rt["overrides"] == list(overrides) == ["implicit_tol=1e-2"] and rt["dt"] == dt
    assert "implicit_tol=1e-2" in bench.format_table({"realtime": [rt]})
