"""A careless or hostile user, through the installed ``rigctl``: every case gets one line naming the file,
field, device or byte, and the documented exit status (rigctl.errors); nothing hangs, nothing is passed
on silently. One class per defect of the hostile-input report, each with cases beyond the one reported.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from tests_support import rigctl_exe  # type: ignore[import-not-found]

from rigctl.errors import EXIT_BAD_INPUT, EXIT_DAMAGED, EXIT_DEVICE, EXIT_USAGE

REPO = Path(__file__).resolve().parents[2]
SIM_RIG = yaml.safe_load((REPO / "rigs" / "sim-3x3.yaml").read_text())


def one_line(res: subprocess.CompletedProcess[str], code: int, *fragments: str) -> str:
    """The run exited with ``code`` and said one line (no traceback) holding every fragment; returns it."""
    assert res.returncode == code, (res.returncode, res.stderr)
    lines = [ln for ln in res.stderr.strip().splitlines() if not ln.startswith("warning:")]
    assert len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


def write_yaml(path: Path, data: Any) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real take of the simulated 3x3 rig at 192x108, three frame sets, and its rectified take."""
    root = tmp_path_factory.mktemp("tiny")
    rig = dict(SIM_RIG, format={**SIM_RIG["format"], "width_px": 192, "height_px": 108})
    write_yaml(root / "tiny.yaml", rig)
    res = subprocess.run(
        [
            *rigctl_exe(),
            "record",
            str(root / "tiny.yaml"),
            "--take",
            "t",
            "--frames",
            "3",
            "--out",
            str(root),
            "--sim",
            "motion=false",
            "--force",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        stdin=subprocess.DEVNULL,
    )
    assert res.returncode == 0, res.stderr
    res = subprocess.run(
        [
            *rigctl_exe(),
            "rectify",
            str(root / "t"),
            "--calibration",
            str(root / "t" / "truth" / "calibration.yaml"),
            "--out",
            str(root / "rect"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        stdin=subprocess.DEVNULL,
    )
    assert res.returncode == 0, res.stderr
    return root


def copy_take(tiny: Path, tmp_path: Path, name: str = "t") -> Path:
    out = tmp_path / f"{name}-copy"
    shutil.copytree(tiny / name, out)
    return out


def essence(take: Path, cam: str) -> Path:
    man = yaml.safe_load((take / "take.yaml").read_text())
    return take / man["cameras"][cam]["essence"]


def corrupt(path: Path, at: int) -> None:
    with open(path, "r+b") as f:
        f.seek(at)
        old = f.read(4)
        f.seek(at)
        f.write(bytes(b ^ 0xFF for b in old))


# ---- 1. YAML: one loader with limits ----------------------------------------------------------------------

BOMB = (
    "spec: 1\n"
    + "a0: &a0 [x, x, x, x, x, x, x, x, x]\n"
    + "".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n" for i in range(1, 9))
)


def test_alias_bomb_rig_file_is_refused_naming_the_limit(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    rig = tmp_path / "bomb.yaml"
    rig.write_text(BOMB)
    assert len(BOMB) < 600
    one_line(run_cli("plan", str(rig)), EXIT_BAD_INPUT, str(rig), "refused: more than 250,000 values once aliases")


@pytest.mark.parametrize(
    ("text", "limit"),
    [
        (
            "spec: 1\n"
            + "".join(f"k{i}: &k{i} 1\n" for i in range(1001))
            + "x: ["
            + ", ".join(f"*k{i}" for i in range(1001))
            + "]\n",
            "more than 1000 aliases",
        ),
        ("spec: 1\nx: " + "[" * 100 + "]" * 100 + "\n", "nested deeper than 64 levels"),
        ("spec: 1\nloop: &l [*l]\n", "nested deeper than 64 levels once aliases are expanded"),
        ("spec: 1\nname: \x07bell\n", "not valid YAML: character '\\x07'"),
    ],
    ids=["aliases", "nesting", "self-reference", "control-character"],
)
def test_every_yaml_limit_is_named(run_cli, tmp_path: Path, text: str, limit: str) -> None:  # type: ignore[no-untyped-def]
    rig = tmp_path / "rig.yaml"
    rig.write_text(text)
    one_line(run_cli("plan", str(rig)), EXIT_BAD_INPUT, str(rig), limit)


def test_every_yaml_reader_has_the_limits(run_cli, tiny: Path, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    # take.yaml
    take = copy_take(tiny, tmp_path)
    (take / "take.yaml").write_text(BOMB)
    one_line(run_cli("take", "info", str(take)), EXIT_BAD_INPUT, str(take / "take.yaml"), "refused")
    # calibration
    cal = tmp_path / "cal.yaml"
    cal.write_text(BOMB)
    res = run_cli("rectify", str(tiny / "t"), "--calibration", str(cal), "--out", str(tmp_path / "r"))
    one_line(res, EXIT_BAD_INPUT, str(cal), "refused")
    # grid.yaml
    grid = tmp_path / "grid"
    grid.mkdir()
    (grid / "grid.yaml").write_text(BOMB)
    cv2.imwrite(str(grid / "r0c0.png"), np.zeros((8, 8, 3), np.uint8))
    one_line(run_cli("depth", str(grid), "--out", str(tmp_path / "d")), EXIT_BAD_INPUT, "grid.yaml", "refused")
    # board description (calibrate --board)
    board = tmp_path / "board.yaml"
    board.write_text(BOMB)
    res = run_cli("calibrate", str(tiny / "t"), "--board", str(board), "--out", str(tmp_path / "c"))
    one_line(res, EXIT_BAD_INPUT, str(board), "refused")


def test_oversized_yaml_is_refused_before_reading(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    rig = tmp_path / "big.yaml"
    with open(rig, "wb") as f:
        f.truncate(16 * 1024 * 1024 + 1)  # sparse: no disk written
    one_line(run_cli("plan", str(rig)), EXIT_BAD_INPUT, str(rig), "over the limit of 16,777,216 bytes")


# ---- 2. damaged data is never passed on --------------------------------------------------------------------


def test_corrupt_frame_refused_by_export_rectify_and_depth(run_cli, tiny: Path, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    take = copy_take(tiny, tmp_path)
    ess = essence(take, "r1c1")
    frame = ess.stat().st_size // 3
    corrupt(ess, frame + 100)  # the second frame
    where = f"{ess}: byte {frame}: frame"
    one_line(
        run_cli("take", "export", str(take), "--out", str(tmp_path / "x")), EXIT_DAMAGED, where, "fails its checksum"
    )
    out = tmp_path / "r"
    res = run_cli("rectify", str(take), "--calibration", str(take / "truth" / "calibration.yaml"), "--out", str(out))
    one_line(res, EXIT_DAMAGED, where, "fails its checksum", "--skip-damaged")
    assert not out.exists()  # no half-rectified take is left behind
    rect = copy_take(tiny, tmp_path, "rect")
    ress = essence(rect, "r0c2")
    corrupt(ress, 10)
    res = run_cli("depth", str(rect), "--out", str(tmp_path / "d"), "--preset", "fast")
    one_line(res, EXIT_DAMAGED, f"{ress}: byte 0: frame", "fails its checksum")


def test_skip_damaged_leaves_out_lists_and_exits_5(run_cli, tiny: Path, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    take = copy_take(tiny, tmp_path)
    ess = essence(take, "r1c1")
    frame = ess.stat().st_size // 3
    corrupt(ess, frame + 100)
    res = run_cli("take", "export", str(take), "--out", str(tmp_path / "x"), "--skip-damaged")
    assert res.returncode == EXIT_DAMAGED and "26 images" in res.stdout
    listed = json.loads((tmp_path / "x" / "export.json").read_text())["skipped_damaged"]
    assert listed == [
        {
            "camera": "r1c1",
            "file": str(ess),
            "byte": frame,
            "problem": listed[0]["problem"],
            "sequence": listed[0]["sequence"],
        }
    ]
    assert not (tmp_path / "x" / "000001" / "r1c1.png").exists() and (tmp_path / "x" / "000001" / "r1c0.png").exists()
    # rectify: the frame is left out, listed in the new take, and never given a fresh checksum
    out = tmp_path / "r"
    res = run_cli(
        "rectify",
        str(take),
        "--calibration",
        str(take / "truth" / "calibration.yaml"),
        "--out",
        str(out),
        "--skip-damaged",
    )
    assert res.returncode == EXIT_DAMAGED, res.stderr
    man = yaml.safe_load((out / "take.yaml").read_text())
    assert [d["byte"] for d in man["damaged_skipped"]] == [frame] and man["cameras"]["r1c1"]["frames"] == 2
    check = run_cli("take", "check", str(out))
    assert check.returncode == 0 and "damaged_skipped: 1 damaged source frame(s) were left out" in check.stderr


@pytest.mark.parametrize("damage", ["empty", "cut-short", "index-record"])
def test_missing_frames_are_damage_not_members_skipped(run_cli, tiny: Path, tmp_path: Path, damage: str) -> None:  # type: ignore[no-untyped-def]
    take = copy_take(tiny, tmp_path)
    ess = essence(take, "r0c2")
    size = ess.stat().st_size
    index = ess.with_suffix(".index")
    if damage == "empty":
        ess.write_bytes(b"")
        expect = (f"{ess}: byte 0: essence file of camera r0c2 is empty, 3 frames claimed",)
    elif damage == "cut-short":
        os.truncate(ess, size // 3)  # frames 1 and 2 are gone: their index records point past the end
        expect = (f"{index}: byte 64: frame at essence offset {size // 3} runs past the end",)
    else:
        corrupt(index, 64 + 20)
        expect = (f"{index}: byte 64: record checksum mismatch",)
    one_line(run_cli("take", "export", str(take), "--out", str(tmp_path / "x")), EXIT_DAMAGED, *expect)
    res = run_cli(
        "rectify", str(take), "--calibration", str(take / "truth" / "calibration.yaml"), "--out", str(tmp_path / "r")
    )
    one_line(res, EXIT_DAMAGED, *expect)
    check = run_cli("take", "check", str(take))
    assert check.returncode == 1 and expect[0] in check.stderr


@pytest.mark.parametrize("target", ["/etc/passwd", "../../../../../../etc/passwd", "symlink"])
def test_manifest_paths_must_stay_inside_the_take(run_cli, tiny: Path, tmp_path: Path, target: str) -> None:  # type: ignore[no-untyped-def]
    take = copy_take(tiny, tmp_path)
    man = yaml.safe_load((take / "take.yaml").read_text())
    if target == "symlink":
        ess = take / man["cameras"]["r0c0"]["essence"]
        ess.unlink()
        ess.symlink_to("/etc/passwd")
        text = man["cameras"]["r0c0"]["essence"]
    else:
        man["cameras"]["r0c0"]["essence"] = text = target
        write_yaml(take / "take.yaml", man)
    expect = f"{take / 'take.yaml'}: cameras.r0c0.essence {text!r} points outside the take folder: refused"
    one_line(run_cli("take", "export", str(take), "--out", str(tmp_path / "x")), EXIT_BAD_INPUT, expect)
    check = run_cli("take", "check", str(take))
    assert check.returncode == 1 and expect in check.stderr


# ---- 3. calibrations make sense ------------------------------------------------------------------------------


def _calibration(tiny: Path, tmp_path: Path, change: Any) -> Path:
    data = yaml.safe_load((tiny / "t" / "truth" / "calibration.yaml").read_text())
    change(data["cameras"])
    return write_yaml(tmp_path / "cal.yaml", data)


def _yaw(cams: dict[str, Any], name: str, rad: float) -> None:
    """Turn one camera about its own centre (R and t together, so the centre stays on the grid)."""
    R, t = np.array(cams[name]["R"]), np.array(cams[name]["t"])
    centre = -R.T @ t
    turn, _ = cv2.Rodrigues(np.array([0.0, rad, 0.0]))
    cams[name]["R"] = (turn @ R).tolist()
    cams[name]["t"] = (-(turn @ R) @ centre).tolist()


def _set(cams: dict[str, Any], cam: str, key: str, *where_value: Any) -> None:
    *where, value = where_value
    target = cams[cam][key]
    for w in where[:-1]:
        target = target[w]
    target[where[-1]] = value


CALIBRATIONS = [
    (lambda c: _set(c, "r1c1", "K", 0, 0, 0.0), "cameras.r1c1.K focal length fx = 0 px is not plausible"),
    (lambda c: _set(c, "r1c1", "K", 1, 1, -400.0), "cameras.r1c1.K focal length fy = -400 px is not plausible"),
    (lambda c: _set(c, "r0c0", "K", 0, 0, 1e9), "cameras.r0c0.K focal length fx = 1e+09 px is not plausible"),
    (lambda c: _set(c, "r2c2", "dist", 0, 1e6), "cameras.r2c2.dist [1000000.0"),
    (lambda c: _set(c, "r1c1", "dist", 0, -20.0), "folds the image back on itself"),
    (lambda c: _set(c, "r1c1", "K", 0, 2, -5.0), "cameras.r1c1.K principal point (-5, "),
    (lambda c: _set(c, "r1c1", "K", 1, 2, 5000.0), "lies outside the 192x108 image"),
    (lambda c: _set(c, "r1c1", "R", 0, 0, 2.0), "cameras.r1c1.R is not a rotation matrix"),
    (lambda c: c["r1c1"].__setitem__("dist", [0.1, 0.0]), "cameras.r1c1.dist must hold 4, 5, 8, 12 or 14 coeff"),
]


@pytest.mark.parametrize(("change", "message"), CALIBRATIONS, ids=[m[:40] for _, m in CALIBRATIONS])
def test_degenerate_calibrations_are_refused(run_cli, tiny: Path, tmp_path: Path, change: Any, message: str) -> None:  # type: ignore[no-untyped-def]
    cal = _calibration(tiny, tmp_path, change)
    res = run_cli("rectify", str(tiny / "t"), "--calibration", str(cal), "--out", str(tmp_path / "r"))
    line = one_line(res, EXIT_BAD_INPUT, message)
    assert f"{cal}:" in line and not (tmp_path / "r").exists()


def test_rectify_names_the_camera_that_makes_the_common_plane_degenerate(run_cli, tiny: Path, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    cal = _calibration(tiny, tmp_path, lambda c: _yaw(c, "r2c0", 0.35))  # a camera turned by 20 degrees
    res = run_cli("rectify", str(tiny / "t"), "--calibration", str(cal), "--out", str(tmp_path / "r"))
    one_line(res, EXIT_BAD_INPUT, f"{cal}: camera r2c0 makes the rectification degenerate", "times the cameras'")
    # a small mounting error is no reason to refuse
    ok = _calibration(tiny, tmp_path, lambda c: _yaw(c, "r2c0", 0.02))
    res = run_cli("rectify", str(tiny / "t"), "--calibration", str(ok), "--out", str(tmp_path / "r2"))
    assert res.returncode == 0, res.stderr


# ---- 4. serial lines and services ----------------------------------------------------------------------------


def _rig_with(tmp_path: Path, **sections: Any) -> Path:
    rig = {k: v for k, v in SIM_RIG.items() if k not in ("tally", "camera_control")}
    rig.update(sections)
    return write_yaml(tmp_path / "rig.yaml", rig)


@pytest.mark.parametrize("port", ["foo://bar", "/dev/null", "/nonexistent/ttyUSB9"])
def test_tally_transport_failures_are_device_errors_naming_the_port(run_cli, tmp_path: Path, port: str) -> None:  # type: ignore[no-untyped-def]
    rig = _rig_with(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": port})
    one_line(run_cli("tally", str(rig), "--program", "r0c0"), EXIT_DEVICE, f"{port}: ")


def test_control_with_unknown_bridge_scheme_is_a_device_error(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    rig = _rig_with(tmp_path, camera_control={"bridge": "foo://bar"})
    one_line(run_cli("control", str(rig), "--gain", "2"), EXIT_DEVICE, "foo://bar: cannot open serial port")


def test_a_pty_line_opens_again_with_even_parity(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    master, slave = os.openpty()
    try:
        rig = _rig_with(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": os.ttyname(slave)})
        for _ in range(3):  # the second open of a configured pty with parity E was EINVAL
            res = run_cli("tally", str(rig), "--program", "r0c0")
            assert res.returncode == 0, res.stderr
            assert len(os.read(master, 4096)) > 0
    finally:
        os.close(master)
        os.close(slave)


# ---- 5. plan at the edges ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ["--near", "1", "--far", "1e155"],
        ["--subject-depth", "1e200"],
        ["--near", "1e300", "--far", "1.7e308"],
        ["--near", "1e-300", "--far", "1"],
    ],
)
def test_plan_json_is_valid_at_any_finite_input(run_cli, argv: list[str]) -> None:  # type: ignore[no-untyped-def]
    res = run_cli("plan", *argv, "--json")
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    plan = json.loads(res.stdout, parse_constant=lambda c: pytest.fail(f"{c} in JSON"))
    assert all(plan[k] is None or np.isfinite(plan[k]) for k in ("near_m", "c0_px", "max_spacing_x_m"))
    for key in plan.get("not_representable", []):  # what is out of double range is named, not inf
        node: Any = plan
        for part in key.split("."):
            node = node[part]
        assert node is None


def test_plan_nearer_than_double_range_is_one_line(run_cli) -> None:  # type: ignore[no-untyped-def]
    one_line(run_cli("plan", "--near", "1e-307", "--far", "1", "--json"), EXIT_USAGE, "near_m 1e-307 is so close")


def test_64x64_plan_groups_pairs_by_offset(tmp_path: Path) -> None:
    from rigctl.plan_report import plan_rig
    from rigctl.rig import load_rig

    n = 64
    rig = dict(
        SIM_RIG,
        grid={**SIM_RIG["grid"], "rows": n, "columns": n},
        cameras=[{"name": f"r{r}c{c}", "device": f"sim://{r}/{c}"} for r in range(n) for c in range(n)],
    )
    rig.pop("tally"), rig.pop("camera_control")
    plan = plan_rig(load_rig(write_yaml(tmp_path / "g.yaml", rig)), subject_depth_m=1.0)
    assert plan.pair_count == (n * n) * (n * n - 1) // 2 and plan.pairs_grouped
    assert len(plan.pairs) == n * n - 1  # one per offset (rows >= 0, |columns|) but (0, 0)
    assert sum(p.same_offset_pairs for p in plan.pairs) == plan.pair_count
    ref = next(p for p in plan.pairs if p.name == plan.reference_pair)
    assert ref.same_offset_pairs == n * (n - 1) and ref.fraction_of_width == pytest.approx(0.04)


def test_grouped_and_listed_plans_agree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from rigctl import plan_report
    from rigctl.rig import load_rig

    rig = load_rig("sim-3x3")
    listed = plan_report.plan_rig(rig, near_m=1.5, far_m=2.5)
    monkeypatch.setattr(plan_report, "LIST_PAIRS_UP_TO", 0)
    grouped = plan_report.plan_rig(rig, near_m=1.5, far_m=2.5)
    assert grouped.pairs_grouped and len(grouped.pairs) < len(listed.pairs) == grouped.pair_count == 36
    by_name = {p.name: p for p in listed.pairs}
    for g in grouped.pairs:
        same = [p for p in listed.pairs if (p.dx_m, p.dy_m) == pytest.approx((g.dx_m, g.dy_m))]
        assert len(same) == g.same_offset_pairs and by_name[g.name].parallax_px == g.parallax_px
    assert grouped.over_budget_count == len(listed.over_budget)


# ---- 6. rig files ---------------------------------------------------------------------------------------------

RIG_TEXT = (REPO / "rigs" / "sim-3x3.yaml").read_text().split("# Camera control through")[0]


def _line(text: str, needle: str, nth: int = 1) -> int:
    lines = [i + 1 for i, ln in enumerate(text.splitlines()) if needle in ln]
    return lines[nth - 1]


@pytest.mark.parametrize(
    ("old", "new", "needle", "nth", "message"),
    [
        (
            "    device: sim://r2c2",
            "    device: sim://r2c1",
            "device: sim://r2c1",
            2,
            "cameras[8].device sim://r2c1 is used by two cameras (cameras[7] too)",
        ),
        (
            "  - name: r2c2",
            "  - name: r1c1",
            "name: r1c1",
            2,
            "cameras[8].name r1c1 appears twice (first as cameras[4])",
        ),
        ("  - name: r2c2", "  - name: r2c5", "name: r2c5", 1, "cameras[8].name r2c5 lies outside the 3x3 grid"),
        ("  rows: 3", "  rows: 4", "rows: 4", 1, "grid.rows is 4 but the cameras use rows 0-2: make it 3"),
        ("  columns: 3", "  columns: 5", "columns: 5", 1, "grid.columns is 5 but the cameras use columns 0-2"),
        ("  rows: 3", "  rows: true", "rows: true", 1, "grid.rows must be a number, got true (a boolean)"),
        ("  fps: 25", "  fps: false", "fps: false", 1, "format.fps must be a number, got false (a boolean)"),
        ("  width_px: 960", "  width_px: '960'", "width_px", 1, "format.width_px must be a whole number, got '960'"),
        (
            "  spacing_x_m: 0.120",
            "  spacing_x_mm: 0.120",
            "spacing_x_mm",
            1,
            "grid.spacing_x_mm is not a known field; did you mean 'spacing_x_m'?",
        ),
        ("  fps: 25", "  fsp: 25", "fsp", 1, "format.fsp is not a known field; did you mean 'fps'?"),
        ("lens:", "lenz:", "lenz", 1, "lenz is not a known field; did you mean 'lens'?"),
        (
            "  fps: 25",
            "  fps: 25\n  pixelformat: UYVY",
            "pixelformat",
            1,
            "format.pixelformat is not a known field; did you mean 'pixel_format'?",
        ),
    ],
)
def test_rig_file_errors_name_the_offending_line(  # type: ignore[no-untyped-def]
    run_cli, tmp_path: Path, old: str, new: str, needle: str, nth: int, message: str
) -> None:
    assert old in RIG_TEXT
    text = RIG_TEXT.replace(old, new, 1)
    rig = tmp_path / "rig.yaml"
    rig.write_text(text)
    one_line(run_cli("plan", str(rig)), EXIT_BAD_INPUT, f"{rig}:{_line(text, needle, nth)}: {message}")


# ---- 7. the command line --------------------------------------------------------------------------------------


def test_exit_codes_are_documented_in_readme_and_errors() -> None:
    import rigctl.errors as errors

    readme = (REPO / "README.md").read_text()
    for code, name in ((1, "check failed"), (2, "usage"), (3, "bad input file"), (4, "device"), (5, "data damaged")):
        assert f"| {code} | {name}" in readme
        assert f"{code}     " in (errors.__doc__ or "")
    assert (errors.DeviceError.exit_code, errors.ProtocolError.exit_code) == (4, 4)
    assert (errors.RigFileError.exit_code, errors.TakeError.exit_code, errors.CalibrationError.exit_code) == (3, 3, 3)
    assert (errors.DamagedDataError.exit_code, errors.ParameterError.exit_code) == (5, 2)


def test_closed_pipe_is_quiet(tmp_path: Path) -> None:
    exe = " ".join(rigctl_exe())
    res = subprocess.run(
        f"{exe} plan rigs/bmd-micro-studio-4k-3x3.yaml --json | head -1; {exe} plan --json | head -c 1",
        shell=True,
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert res.stdout.startswith("{\n{") and res.stderr == ""


def test_python_dash_m_and_debug_anywhere(tmp_path: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "rigctl", "plan", "--near", "3", "--far", "2"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    one_line(res, EXIT_USAGE, "rigctl plan: error: far_m must be >= near_m")
    for argv in (
        ["--debug", "plan", "--near", "3", "--far", "2"],
        ["plan", "--near", "3", "--debug", "--far", "2"],
        ["plan", "--near", "3", "--far", "2", "--debug"],
    ):
        res = subprocess.run([sys.executable, "-m", "rigctl", *argv], capture_output=True, text=True, cwd=tmp_path)
        assert res.returncode != 0 and "Traceback" in res.stderr and "ParameterError" in res.stderr, argv


# ---- resources and races -------------------------------------------------------------------------------------


def test_sdi_bridge_decoder_keeps_bounded_error_history() -> None:
    from rigctl.drivers.protocols.sdi_bridge import SYNC, FrameDecoder

    dec = FrameDecoder()
    rng = np.random.default_rng(3)
    for _ in range(100):  # 400 KB of garbage full of false syncs
        chunk = bytearray(rng.integers(0, 256, 4000, dtype=np.uint8).tobytes())
        for i in range(0, 4000, 20):
            chunk[i : i + 2] = SYNC
        dec.feed(bytes(chunk))
    assert dec.error_count > 5_000 and len(dec.errors) == FrameDecoder.KEEP_ERRORS


def test_killed_take_reserve_is_removed_when_next_read(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import fcntl
    import signal
    import time

    from rigctl.take.reserve import create_reserve, remove_stale_reserves

    proc = subprocess.Popen(
        [
            *rigctl_exe(),
            "record",
            "--take",
            "k",
            "--frames",
            "2000",
            "--out",
            str(tmp_path),
            "--sim",
            "motion=false",
            "--force",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        stdin=subprocess.DEVNULL,
    )
    index = tmp_path / "k" / "cameras" / "r2c2.index"
    for _ in range(1200):  # waits for the state, asserts nothing about time
        if index.exists() and index.stat().st_size >= 4 * 64:
            break
        time.sleep(0.05)
    reserve = tmp_path / "k" / ".reserve"
    assert reserve.exists()
    # while the recorder runs, its reserve is not stale
    assert remove_stale_reserves([tmp_path / "k"]) == []
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert reserve.exists() and reserve.stat().st_size == 1 << 20
    res = run_cli("take", "check", str(tmp_path / "k"))
    assert res.returncode == 0, res.stderr
    assert not reserve.exists()
    # a reserve this process holds is left alone
    fd = create_reserve(tmp_path, 16)
    try:
        assert remove_stale_reserves([tmp_path]) == [] and (tmp_path / ".reserve").exists()
        fcntl.flock(fd, fcntl.LOCK_UN)
        assert remove_stale_reserves([tmp_path]) == [tmp_path / ".reserve"]
    finally:
        os.close(fd)


def test_writers_close_only_after_the_flush_thread_ends(tmp_path: Path) -> None:
    """'flushing r2c2: Bad file descriptor' at the end of a take: the flush thread was still syncing files the
    ending take had closed. A flush that began before the end must end before any writer closes."""
    import threading

    from rigctl.recorder import Recorder, TakePlan
    from rigctl.registry import open_cameras
    from rigctl.rig import load_rig
    from rigctl.take.writer import CameraWriter

    trace: list[str] = []
    syncing = threading.Event()
    holder: dict[str, Recorder] = {}

    class Traced(CameraWriter):
        def sync(self) -> None:
            if threading.current_thread().name != "syncer":  # close() syncs its own files last: not traced
                super().sync()
                return
            trace.append("sync-start")
            syncing.set()
            holder["rec"]._finished.wait(30)  # a slow flush: still running when the take ends
            trace.append("sync-end")
            super().sync()

        def close(self) -> None:
            trace.append("close")
            super().close()

    rig = load_rig("sim-3x3")
    devices = open_cameras(rig, ["motion=false", "noise=0"], ["r0c0", "r0c1"])
    plan = TakePlan.spread("t", [tmp_path], sorted(devices.cameras))
    rec = holder["rec"] = Recorder(rig, devices, plan, writer_factory=Traced)
    rec.sync_interval_s = 0.01
    rec.arm()
    rec.start(200)
    assert syncing.wait(30)
    rec.stop()
    man = rec.finish()
    assert man["status"] in ("complete", "ended") and "close" in trace
    first_close = trace.index("close")
    assert trace[:first_close].count("sync-start") == trace[:first_close].count("sync-end")
    assert "sync-start" not in trace[first_close:]


def test_tally_service_never_dies_silently(tmp_path: Path) -> None:
    """The service on a port with an unknown scheme: the error shows in its state and it keeps retrying; on
    an error that is not the line's (a bug) it stops, and says so."""
    import threading

    from rigctl.errors import DeviceError
    from rigctl.registry import open_tally
    from rigctl.rig import load_rig
    from rigctl.tally import TallyService, TallyState

    rig = load_rig(_rig_with(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": "foo://bar"}))
    attempts: list[str] = []
    retried = threading.Event()

    def opener() -> Any:
        attempts.append("open")
        if len(attempts) >= 3:
            retried.set()
        return open_tally(rig)

    svc = TallyService(opener, port_path="foo://bar")
    svc.BACKOFF_S = (0.0,)  # retry at once: the test waits for attempts, not for time
    svc.start()
    try:
        assert retried.wait(30)
        assert not svc.connected and svc.running and svc.stopped_by == ""
        assert svc.last_error.startswith("foo://bar: cannot open serial port")
    finally:
        svc.stop()
    with pytest.raises(DeviceError, match="foo://bar"):
        open_tally(rig)

    def broken() -> Any:
        raise ValueError("a bug in an output driver")

    svc = TallyService(broken).start()
    svc._thread.join(30)
    assert not svc.running and not svc.connected
    assert svc.last_error == svc.stopped_by == "tally service stopped: ValueError: a bug in an output driver"
    svc.set(TallyState(program=frozenset({"r0c0"})))  # setting state on a stopped service does not hang
