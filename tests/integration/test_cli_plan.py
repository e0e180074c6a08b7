"""``rigctl plan`` through the installed console script: the paper's figure, JSON contract, bad input."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PAPER = str(REPO / "rigs" / "bmd-micro-studio-4k-3x3.yaml")


def test_paper_figure_through_the_cli(run_cli) -> None:  # type: ignore[no-untyped-def]
    # the contract's own spelling, run from a directory that has no rigs/ folder
    out = run_cli("plan", "rigs/bmd-micro-studio-4k-3x3.yaml", "--subject-depth", "1.0", "--json")
    assert out.returncode == 0, out.stderr
    plan = json.loads(out.stdout)
    assert plan["near_m"] == pytest.approx(1.948, abs=1e-3)
    assert plan["far_m"] == pytest.approx(plan["near_m"] + 1.0)
    assert plan["c0_px"] == pytest.approx(7352.9, abs=0.05)
    assert plan["budget_fraction"] == 0.04
    assert plan["disparity_range_px"] == {"min": 299, "max": 453}
    assert len(plan["pairs"]) == 36
    for key in ("name", "baseline_m", "parallax_px", "fraction_of_width", "within_budget"):
        assert all(key in p for p in plan["pairs"])
    by_name = {p["name"]: p for p in plan["pairs"]}
    assert by_name["r0c0-r0c1"]["within_budget"] is True
    assert by_name["r0c0-r0c1"]["fraction_of_width"] == pytest.approx(0.04, rel=1e-9)
    # the vertical pair takes 4.6 % of the height and the outer columns 8 % of the width: both over
    assert by_name["r0c0-r1c0"]["within_budget"] is False
    assert by_name["r0c0-r1c0"]["fraction_of_height"] == pytest.approx(0.046, abs=5e-4)
    assert by_name["r0c0-r0c2"]["fraction_of_width"] == pytest.approx(0.08, abs=5e-4)
    horizontal = [p for p in plan["pairs"] if p["dy_m"] == 0 and p["dx_m"] == pytest.approx(0.12)]
    assert len(horizontal) == 6 and all(p["within_budget"] for p in horizontal)
    assert plan["near_m_all_pairs"] > plan["near_m"]


def test_check_mode_names_pairs_over_budget(run_cli) -> None:  # type: ignore[no-untyped-def]
    out = run_cli("plan", PAPER, "--near", "1.5", "--far", "2.5")
    assert out.returncode == 0, out.stderr
    assert "OVER" in out.stdout and "pairs exceed the budget" in out.stdout
    assert "r0c0-r0c1" in out.stdout
    ok = run_cli("plan", PAPER, "--near", "4", "--far", "5", "--json")
    plan = json.loads(ok.stdout)
    assert plan["all_within_budget"] is True and not plan["solved_near"]


def test_far_at_infinity_and_near_equals_far(run_cli) -> None:  # type: ignore[no-untyped-def]
    out = run_cli("plan", PAPER, "--near", "10", "--far", "inf", "--json")
    assert out.returncode == 0, out.stderr
    plan = json.loads(out.stdout)  # strict JSON: no Infinity or NaN tokens
    assert plan["far_m"] is None and plan["far_at_infinity"] is True
    assert plan["disparity_range_px"]["min"] == 0
    by_name = {p["name"]: p for p in plan["pairs"]}
    assert by_name["r0c0-r0c1"]["parallax_px"] == pytest.approx(7352.94 * 0.12 / 10, rel=1e-6)
    flat = json.loads(run_cli("plan", PAPER, "--near", "3", "--far", "3", "--json").stdout)
    assert all(p["parallax_px"] == 0 for p in flat["pairs"])
    assert flat["max_spacing_x_m"] is None  # unbounded, not infinity


def test_default_rig_and_human_table(run_cli) -> None:  # type: ignore[no-untyped-def]
    out = run_cli("plan")
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("rig sim-3x3: 960x540 px")
    assert "near 1.948 m" in out.stdout  # same angles as the paper's rig at a quarter of the pixels


def test_solved_near_keeps_subject_in_every_camera(run_cli) -> None:  # type: ignore[no-untyped-def]
    out = run_cli("plan", PAPER, "--subject-depth", "1", "--subject-width", "0.6", "--json")
    plan = json.loads(out.stdout)
    # one camera sees about 1.02 m at 1.948 m; the outer columns are 0.24 m apart
    assert plan["view_at_near_m"]["width"] == pytest.approx(13.056 * 1.948 / 25, abs=2e-3)
    assert plan["subject_fits"] == {"width": True}
    wide = json.loads(run_cli("plan", PAPER, "--subject-depth", "1", "--subject-width", "0.9", "--json").stdout)
    assert wide["subject_fits"] == {"width": False}


BAD = [
    (["--near", "0", "--far", "2"], "--near: must be a positive distance"),
    (["--near", "-1", "--far", "2"], "--near: must be a positive distance"),
    (["--near", "nan", "--far", "2"], "--near: not a number"),
    (["--near", "abc", "--far", "2"], "--near: not a number"),
    (["--near", "inf", "--far", "inf"], "--near: must be a positive distance"),
    (["--near", "2", "--far", "-3"], "--far: must be a positive distance"),
    (["--near", "3", "--far", "2"], "far_m must be >= near_m, got far_m=2.0 < near_m=3.0"),
    (["--subject-depth", "-1"], "--subject-depth: must be a depth >= 0"),
    (["--subject-depth", "0"], "is a flat subject"),
    (["--subject-depth", "nan"], "--subject-depth: not a number"),
    (["--subject-depth", "inf"], "--subject-depth: must be a depth >= 0"),
    (["--subject-width", "-1"], "--subject-width: must be a width >= 0 in metres"),  # it said "a depth"
    (["--subject-height", "inf"], "--subject-height: must be a height >= 0 in metres"),
    (["--budget", "0"], "--budget: must be a fraction in (0, 1]"),
    (["--budget", "1.5"], "--budget: must be a fraction in (0, 1]"),
    (["--budget", "nan"], "--budget: must be a fraction"),
    (["--near", "2"], "near_m given without far_m"),
    (["--far", "2", "--subject-depth", "3"], "subject_depth_m 3.0 is not less than far_m 2.0"),
    (["--near", "1", "--far", "2", "--subject-depth", "1"], "not all three"),
    # distances no camera can be planned for: they printed hundreds of digits, or near = far = 0.000 m
    (["--near", "1e-300", "--far", "1e-299"], "--near 1e-300 m: a plan's distances run from 0.001 m to 1e+06 m"),
    (["--near", "1", "--far", "1e155"], "--far 1e+155 m: a plan's distances run from 0.001 m to 1e+06 m (inf for"),
    (["--near", "0.0009", "--far", "1", "--json"], "--near 0.0009 m: a plan's distances run from 0.001 m"),
    (["--subject-depth", "1e200"], "--subject-depth 1e+200 m: at most 1e+06 m"),
    (["--subject-depth", "1e-300"], "--subject-depth 1e-300 m: the subject's near side would be 2.4e-150 m"),
    (["--far", "2", "--subject-depth", "1.99999"], "--far 2 m and --subject-depth 1.99999 m: the subject's near"),
]


@pytest.mark.parametrize(("argv", "message"), BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_is_one_line_and_exit_2(run_cli, argv: list[str], message: str) -> None:  # type: ignore[no-untyped-def]
    out = run_cli("plan", *argv)
    assert out.returncode == 2  # usage: a bad option or parameter value
    assert out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert message in lines[0]
    assert "Traceback" not in out.stderr


def test_the_text_report_stays_readable_at_its_extremes(run_cli) -> None:  # type: ignore[no-untyped-def]
    """At the edges of the distances a plan holds (1 mm to 1,000 km) the report's numbers keep a readable width
    (a far depth error printed 1133333333333.33 mm); the JSON keeps them whole."""
    out = run_cli("plan", "--near", "0.001", "--far", "1e6")
    assert out.returncode == 0, out.stderr
    assert "1.133e+12 mm at far" in out.stdout
    assert not re.search(r"[0-9]{11}", out.stdout), out.stdout
    whole = json.loads(run_cli("plan", "--near", "0.001", "--far", "1e6", "--json").stdout)
    assert whole["depth_error_mm"]["at_far"] == pytest.approx(1133333333333.33, rel=1e-6)


def test_the_report_never_prints_hundreds_of_digits() -> None:
    """The library still plans what the CLI refuses; its text report stays in columns whatever the numbers."""
    from rigctl.planning.report import plan_rig
    from rigctl.planning.text import format_plan
    from rigctl.rig import load_rig

    rig = load_rig("sim-3x3")
    text = format_plan(plan_rig(rig, near_m=1e-300, far_m=1e-299), rig)
    assert not re.search(r"[0-9]{11}", text) and max(map(len, text.splitlines())) < 130, text
    table = [ln for ln in text.splitlines() if ln.startswith(("vertical", "horizontal", "diagonal"))]
    assert table and all(len(ln.split()) == 10 for ln in table), table  # every column apart from its neighbour


def test_bad_rig_file_names_file_line_field(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    text = (REPO / "rigs" / "sim-3x3.yaml").read_text().replace("spacing_x_m: 0.120", "spacing_x_m: -0.12")
    rig = tmp_path / "x.yaml"
    rig.write_text(text)
    out = run_cli("plan", str(rig))
    assert out.returncode == 3  # bad input file
    assert out.stderr.strip() == f"rigctl plan: error: {rig}:20: grid.spacing_x_m must be > 0, got -0.12"


def test_missing_rig_file_is_a_bad_input_file(run_cli) -> None:  # type: ignore[no-untyped-def]
    out = run_cli("plan", "no-such-rig.yaml")
    assert out.returncode == 3 and out.stdout == ""
    assert out.stderr.strip().startswith("rigctl plan: error: no-such-rig.yaml: no such rig file")


def test_debug_shows_the_traceback(run_cli) -> None:  # type: ignore[no-untyped-def]
    out = run_cli("--debug", "plan", "--near", "3", "--far", "2")
    assert out.returncode != 0 and "Traceback" in out.stderr


def test_json_numbers_are_always_finite(run_cli) -> None:  # type: ignore[no-untyped-def]
    for argv in (
        ["--near", "0.01", "--far", "10000"],
        ["--subject-depth", "1e-6"],  # the smallest a plan holds (1e-9 is now refused: near 0.07 mm)
        ["--near", "5", "--far", "inf"],
    ):
        out = run_cli("plan", PAPER, *argv, "--json")
        assert out.returncode == 0, out.stderr

        def walk(v: object) -> None:
            if isinstance(v, float):
                assert math.isfinite(v)
            elif isinstance(v, dict):
                for x in v.values():
                    walk(x)
            elif isinstance(v, list):
                for x in v:
                    walk(x)

        walk(json.loads(out.stdout))
