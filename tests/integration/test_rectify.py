"""``rigctl rectify`` on a recorded simulated take: the result is a take, its images line up with the true
disparity as the contract defines it, tables come from the cache the second time, and bad input is refused."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from warp_check import STEP, mae_against_neighbours

from rigctl.calibration_model import load_calibration
from rigctl.pfm import read_pfm
from rigctl.take.reader import TakeReader

SIM = ["motion=false", "noise=0", "exposure_spread=0", "colour_spread=0", "vignetting=0", "mount_position_mm=0.5"]


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    from tests_support import run_rigctl

    out = module_tmp("takes")
    args = ["record", "--take", "t", "--frames", "2", "--out", str(out)]
    res = run_rigctl(*args, *[a for s in SIM for a in ("--sim", s)])
    assert res.returncode == 0, res.stderr
    return out / "t"


def grey(reader: TakeReader, name: str, i: int = 0) -> np.ndarray:
    rgb = reader.frame_rgb(name, i)
    return np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) * 255, dtype=np.float32)


def test_rectified_take_lines_up_with_the_truth(take: Path, tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "rect"
    res = run_cli(
        "rectify", str(take), "--calibration", str(take / "truth" / "calibration.yaml"), "--out", str(out), "--json"
    )
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["frames"] == 18 and summary["remap_s"] > 0
    rect = TakeReader(out)
    assert rect.pixel_format == "BGR3" and rect.names == TakeReader(take).names
    assert len(rect.complete_sets()) == 2
    record = rect.manifest.rectification
    assert record is not None
    assert record.calibration_sha256 and np.asarray(record.K).shape == (3, 3)
    # the contract: a point at x in r1c1 is at x - d * (k - j) in its horizontal neighbours, and at
    # y - d * dy/dx * (m - i) below, with the cameras' true positions in the rectified frame
    truth = take / "truth" / "disparity"
    frame_dir = sorted(truth.iterdir())[0]
    disps = {n: read_pfm(frame_dir / f"{n}.pfm") for n in ("r1c1", *STEP)}
    images = {n: grey(rect, n) for n in disps}
    pos = {n: np.asarray(p) for n, p in record.positions_m.items()}
    offsets = {n: tuple((pos[n] - pos["r1c1"])[:2] / record.spacing_x_m) for n in STEP}
    result = mae_against_neighbours(images, disps, offsets)  # type: ignore[arg-type]
    for name, (mae, pixels) in result.items():
        assert pixels > 15000 and mae < 3.0, (name, mae, pixels)
    # the unrectified take does not line up: rectification did the work
    raw = {n: grey(TakeReader(take), n) for n in disps}
    unrect = mae_against_neighbours(raw, disps, offsets)  # type: ignore[arg-type]
    assert np.mean([v[0] for v in unrect.values()]) > 2 * np.mean([v[0] for v in result.values()])
    # the rectified take is a take like any other
    assert run_cli("take", "check", str(out)).returncode == 0
    # but not one to rectify again: a second warp only resamples (and blurs) what is already in the plane
    cal = str(take / "truth" / "calibration.yaml")
    again = run_cli("rectify", str(out), "--calibration", cal, "--out", str(tmp_path / "r2"))
    assert again.returncode == 2 and again.stderr.count("\n") == 1 and "already rectified" in again.stderr
    assert not (tmp_path / "r2").exists()


def test_tables_are_cached_by_calibration_hash(take: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from rigctl.rectification.rectify import Rectifier

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    calib = load_calibration(take / "truth" / "calibration.yaml")
    first = Rectifier(calib)
    assert not first.cache_hit and len(list((tmp_path / "rigctl" / "remap").glob("*.npz"))) == 1
    second = Rectifier(calib)
    assert second.cache_hit and second.hash == first.hash
    for n in calib.names:
        assert np.array_equal(first.maps[n][0], second.maps[n][0])
    # a damaged cache entry is rebuilt, not trusted
    (tmp_path / "rigctl" / "remap" / f"{first.hash}.npz").write_bytes(b"not a table")
    third = Rectifier(calib)
    assert not third.cache_hit and np.array_equal(third.maps["r0c0"][0], first.maps["r0c0"][0])


def test_swapped_cameras_are_an_error(take: Path, tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    data = yaml.safe_load((take / "truth" / "calibration.yaml").read_text())
    cams = data["cameras"]
    cams["r1c0"], cams["r1c2"] = cams["r1c2"], cams["r1c0"]
    bad = tmp_path / "swapped.yaml"
    bad.write_text(yaml.safe_dump(data))
    res = run_cli("rectify", str(take), "--calibration", str(bad), "--out", str(tmp_path / "r"))
    assert res.returncode == 3  # bad input file
    assert "camera order does not match the geometry" in res.stderr
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("problem", ["missing_camera", "wrong_size", "existing_out"])
def test_bad_input_is_one_line(take: Path, tmp_path: Path, run_cli, problem: str) -> None:  # type: ignore[no-untyped-def]
    data = yaml.safe_load((take / "truth" / "calibration.yaml").read_text())
    out = tmp_path / "r"
    if problem == "missing_camera":
        del data["cameras"]["r2c2"]
        message = "no calibration for camera(s) r2c2"
    elif problem == "wrong_size":
        for cam in data["cameras"].values():
            cam["image_size"] = [1920, 1080]
        message = "does not match take"
    else:
        out.mkdir()
        message = "already exists"
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(data))
    res = run_cli("rectify", str(take), "--calibration", str(path), "--out", str(out))
    assert res.returncode == 3 and message in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_out_inside_the_source_truth_is_one_line_and_copies_nothing(take: Path, tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    """The new take copies the source's truth/: an --out inside it copied the copy into itself until the path
    was too long (27 MB written, a 123 KB error line, exit 4)."""
    import shutil

    src = tmp_path / "t"
    shutil.copytree(take, src)
    before = sorted(str(p.relative_to(src)) for p in src.rglob("*"))
    out = src / "truth" / "rect"
    res = run_cli("rectify", str(src), "--calibration", str(take / "truth" / "calibration.yaml"), "--out", str(out))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and len(res.stderr) < 300, res.stderr
    assert "lies in the source take's truth/" in res.stderr
    assert sorted(str(p.relative_to(src)) for p in src.rglob("*")) == before


def test_board_writes_a_detectable_target(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    from rigctl.board import BoardSpec

    res = run_cli("board", "--out", str(tmp_path / "b"), "--squares", "6x4", "--square-mm", "40", "--marker-mm", "30")
    assert res.returncode == 0, res.stderr
    spec = BoardSpec.load(tmp_path / "b.yaml")
    assert (spec.squares_x, spec.squares_y, spec.square_m) == (6, 4, 0.04)
    img = cv2.imread(str(tmp_path / "b.png"), cv2.IMREAD_GRAYSCALE)
    detector = cv2.aruco.CharucoDetector(spec.board())
    _, ids, _, _ = detector.detectBoard(img)
    assert ids is not None and len(ids) == 5 * 3  # every inner corner
    res = run_cli("board", "--out", str(tmp_path / "c"), "--marker-mm", "80")
    assert res.returncode == 2, res.stderr
    assert "--marker-mm 80 must be at least 0.1 mm and smaller than --square-mm 75" in res.stderr


def test_rectified_take_keeps_the_source_timecodes(take: Path, tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    """Frames that carry timecode (here 23:59:59:24 and 00:00:00:00 at 25 fps, across midnight) keep it
    through rectify; frame sets are then built on it."""
    import shutil

    from rigctl.interfaces import FrameFlags
    from rigctl.take import index
    from rigctl.timecode import Timecode

    src = tmp_path / "tc"
    shutil.copytree(take, src)
    labels = [Timecode.parse("23:59:59:24", 25), Timecode.parse("00:00:00:00", 25)]
    reader = TakeReader(src)
    for name in reader.names:  # the index as a driver with timecode would have written it
        buf = bytearray(index.RECORD_SIZE)
        with open(reader.index_path(name), "wb") as f:
            for rec, tc in zip(reader.index[name], labels, strict=True):
                flags = int(rec["flags"]) | FrameFlags.TIMECODE
                fields = [int(rec[k]) for k in ("sequence", "capture_ns", "host_ns")]
                index.pack_into(
                    buf,
                    *fields,
                    flags,
                    int(rec["offset"]),
                    int(rec["size"]),
                    int(rec["crc"]),
                    int(rec["set"]),
                    tc.frames,
                )
                f.write(buf)
    out = tmp_path / "rect"
    res = run_cli("rectify", str(src), "--calibration", str(take / "truth" / "calibration.yaml"), "--out", str(out))
    assert res.returncode == 0, res.stderr
    rect = TakeReader(out)
    for name in rect.names:
        assert [str(rect.timecode(name, i)) for i in range(2)] == ["23:59:59:24", "00:00:00:00"]
    assert [str(rect.set_timecode(s)) for s in rect.frame_sets] == ["23:59:59:24", "00:00:00:00"]
    assert all(s.complete(rect.names) for s in rect.frame_sets)
