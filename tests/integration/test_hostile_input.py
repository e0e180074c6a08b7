"""A careless or hostile user, through the installed ``rigctl``: every case gets one line naming the file,
field, device or byte, and the documented exit status (rigctl.errors); nothing hangs, nothing is passed
on silently. One class per defect of the hostile-input report, each with cases beyond the one reported.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from hostile_support import SIM_RIG, one_line, write_yaml  # type: ignore[import-not-found]
from tests_support import rigctl_exe  # type: ignore[import-not-found]

from rigctl.errors import EXIT_BAD_INPUT, EXIT_DAMAGED


@pytest.fixture(scope="module")
def tiny(module_tmp: Callable[[str], Path]) -> Path:
    """A real take of the simulated 3x3 rig at 192x108, three frame sets, and its rectified take."""
    root = module_tmp("tiny")
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


@pytest.mark.parametrize("layout", ["frames", "sequence"])
def test_a_failed_export_leaves_no_half_written_frame_set(run_cli, tiny: Path, tmp_path: Path, layout: str) -> None:  # type: ignore[no-untyped-def]
    """The last camera's frame of frame set 1 is damaged: frame set 0 stays whole, nothing of frame set 1 is left
    (its eight good pictures were once published, the ninth refused), and no hidden staging folder either."""
    take = copy_take(tiny, tmp_path)
    ess = essence(take, "r2c2")
    frame = ess.stat().st_size // 3
    corrupt(ess, frame + 100)
    out = tmp_path / "x"
    res = run_cli("take", "export", str(take), "--out", str(out), "--layout", layout)
    one_line(res, EXIT_DAMAGED, f"{ess}: byte {frame}: frame", "fails its checksum")
    record = json.loads((out / "export.json").read_text())  # the record: what the stopped run may have written
    planned = "000001/r0c0.png" if layout == "frames" else "r0c0/r0c0.000001.png"
    assert not record["complete"] and planned in record["files"]
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.name != "export.json")
    cams = [f"r{r}c{c}" for r in range(3) for c in range(3)]
    if layout == "frames":
        assert files == [f"000000/{c}.png" for c in cams]
    else:
        assert files == [f"{c}/{c}.000000.png" for c in cams]
    assert not [p for p in out.rglob(".*")], "a staging folder or temporary file is left"


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
    info = run_cli("take", "info", str(take))  # a summary still shows, and says where to look
    assert info.returncode == 0 and "damaged item(s); rigctl take check" in info.stderr


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


@pytest.mark.parametrize(
    ("frame", "code", "said"),
    [
        ("9999999999999", EXIT_BAD_INPUT, "frame 9999999999999 is past the end of the file"),  # beyond an offset
        ("99999999999999999999999", EXIT_BAD_INPUT, "is past the end of the file"),
        ("2", EXIT_BAD_INPUT, "frame 2 is past the end of the file"),
        ("-1", 2, "--frame: must be at least 0, got '-1'"),
    ],
)
def test_ivpsnr_frame_out_of_the_file_is_one_line(run_cli, tmp_path: Path, frame: str, code: int, said: str) -> None:  # type: ignore[no-untyped-def]
    pic = tmp_path / "a.yuv"
    pic.write_bytes(bytes(16 * 8 * 3 // 2 * 2) * 2)  # two 16x8 10-bit 4:2:0 frames of zeros
    res = run_cli("miv", "ivpsnr", str(pic), str(pic), "--size", "16x8", "--pix-fmt", "yuv420p10le", "--frame", frame)
    one_line(res, code, said)
