"""Timecode through takes, and EXR that compositing and engines take as they are.

Takes here are written with the real take writer (essence, index, manifest on disk) from frames that carry
timecodes, as the V4L2 driver hands them over, and are read back with the real reader and CLI.
"""

from __future__ import annotations

import csv
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from timecode import Timecode as Reference  # an independent implementation

from rigctl.exr import REC709_CHROMATICITIES, read_exr
from rigctl.interfaces import CaptureFormat, Frame, FrameFlags
from rigctl.take.accounting import CameraStats
from rigctl.take.framesets import FrameSet
from rigctl.take.manifest import TAKE_SPEC, Manifest, write_manifest
from rigctl.take.reader import TakeReader
from rigctl.take.sidecars import write_ale, write_sets_csv
from rigctl.take.writer import CameraWriter
from rigctl.timecode import Timecode, rate_of, start_timecode

W, H = 64, 48
GREY = 104  # BT.709 code value of 18 % grey: 1.099 * 0.18 ** 0.45 - 0.099 = 0.409 = 104.3 / 255
RATES = [(24000 / 1001, "23.976"), (25.0, "25"), (30000 / 1001, "29.97"), (50.0, "50"), (60000 / 1001, "59.94")]


def picture() -> np.ndarray:
    """BGR: a green screen with a grey patch in the middle."""
    img = np.zeros((H, W, 3), np.uint8)
    img[...] = (20, 190, 20)
    img[14:34, 22:42] = GREY
    return img


def write_take(folder: Path, fps: float, frames: dict[str, list[Timecode | None]], period_ns: int = 0) -> Path:
    """A take of BGR3 frames; camera -> the timecode of each frame (None: the frame carries none)."""
    period_ns = period_ns or round(1e9 / fps)
    data = picture()
    cams = {}
    for ci, (name, tcs) in enumerate(frames.items()):
        writer = CameraWriter(name, folder, fps, sync_interval_s=0)
        wrap, last = 0, None  # capture time is monotonic: a timecode past midnight counts on from the day before
        for i, tc in enumerate(tcs):
            flags = FrameFlags.TIMESTAMP_MONOTONIC
            n = tc.frames if tc else i
            if last is not None and n + wrap < last:
                wrap += last - n + 1
            last = n + wrap
            t = 10**12 + last * period_ns + ci * 1000
            writer.write(Frame(name, i, t, t + 10**6, flags, memoryview(data.reshape(-1)), tc))
        writer.close()
        cams[name] = {"essence": f"{name}.essence", "index": f"{name}.index", "frames": len(tcs)}
    write_manifest(
        folder,
        Manifest.model_validate(
            {
                "spec": TAKE_SPEC,
                "take": folder.name,
                "status": "complete",
                "started_utc": "2026-05-01T10:20:30.500+00:00",
                "format": {"width": W, "height": H, "pixel_format": "BGR3", "fps": fps, "bytes_per_frame": W * H * 3},
                "timing": {"frame_period_ns": period_ns},
                "cameras": cams,
            }
        ),
    )
    return folder


def labels(start: str, count: int, fps: float) -> list[Timecode]:
    first = Timecode.parse(start, rate_of(fps)[0])
    return [first + k for k in range(count)]


@pytest.mark.parametrize(("fps", "name"), RATES)
def test_frame_sets_by_timecode_are_exact_at_every_rate(tmp_path: Path, fps: float, name: str) -> None:
    """Across a minute whose first labels are dropped (29.97/59.94 DF), a camera that lost one frame leaves
    a gap at exactly that label and no two frames share a set."""
    rate, drop = rate_of(fps)
    sep = ";" if drop else ":"
    tcs = labels(f"00:00:59{sep}{rate - 6:02d}", 12, fps)
    lost = 7  # the second frame after the minute turns
    folder = write_take(tmp_path / "t", fps, {"r0c0": tcs, "r0c1": tcs[:lost] + tcs[lost + 1 :]})
    reader = TakeReader(folder)
    sets = reader.frame_sets
    assert len(sets) == 12
    assert [s.number for s in sets if not s.complete(reader.names)] == [lost]
    got = [str(reader.set_timecode(s)) for s in sets]
    # the labels are the reference library's, one frame apart
    first = Reference(name, got[0])
    assert got == [str(Reference(name, frames=first.frames + k)) for k in range(12)]
    if drop:
        assert got[6] == "00:01:00;" + ("02" if rate == 30 else "04")  # the dropped labels are skipped ...
    for s in sets:  # ... and every member of a set carries the set's own label
        assert {str(reader.timecode(c, i)) for c, i in s.members.items()} == {str(reader.set_timecode(s))}


def test_the_labels_that_once_collided_are_two_sets(tmp_path: Path) -> None:
    fps = 30000 / 1001
    tcs = [Timecode.parse(t, 30) for t in ("00:00:16;28", "00:00:16;29", "00:00:17;00", "00:00:17;01")]
    reader = TakeReader(write_take(tmp_path / "t", fps, {"r0c0": tcs, "r0c1": tcs}))
    assert [str(reader.set_timecode(s)) for s in reader.frame_sets] == [str(t) for t in tcs]
    assert all(s.complete(reader.names) for s in reader.frame_sets)


def test_a_take_past_midnight_keeps_its_order(tmp_path: Path) -> None:
    tcs = labels("23:59:59:22", 6, 25.0)
    reader = TakeReader(write_take(tmp_path / "t", 25.0, {"r0c0": tcs, "r0c1": tcs}))
    assert [str(reader.set_timecode(s)) for s in reader.frame_sets] == [
        "23:59:59:22", "23:59:59:23", "23:59:59:24", "00:00:00:00", "00:00:00:01", "00:00:00:02",
    ]  # fmt: skip


def test_sidecars_use_the_frames_timecode_else_the_time_of_day(tmp_path: Path) -> None:
    fmt = CaptureFormat(W, H, "BGR3", 30000 / 1001)
    started = "2026-05-01T10:20:30.500+00:00"
    stats = {n: CameraStats(n, written=[(k, k) for k in range(100)]) for n in ("r0c0", "r0c1")}
    stats["r0c1"].first_timecode = Timecode.parse("01:00:59;29", 30)
    write_ale(tmp_path / "t.ale", "t", started, fmt, ["r0c0", "r0c1"], stats)
    rows = (tmp_path / "t.ale").read_text().splitlines()
    data = {r.split("\t")[0]: r.split("\t") for r in rows[rows.index("Data") + 1 :]}
    tod = start_timecode(started, fmt.fps)
    assert data["t_r0c0"][2:4] == [str(tod), str(tod + 100)]
    assert data["t_r0c1"][2:4] == ["01:00:59;29", "01:01:03;11"]  # 100 frames on, across a dropped pair
    assert data["t_r0c1"][3] == str(Reference("29.97", "01:00:59;29") + 100)
    sets = [FrameSet(k, k, {"r0c0": k}, 0) for k in range(3)]
    write_sets_csv(tmp_path / "sets.csv", sets, ["r0c0"], stats, tod)
    with open(tmp_path / "sets.csv") as f:
        assert [r["timecode"] for r in csv.DictReader(f)] == [str(tod + k) for k in range(3)]


def test_the_shoot_ui_counts_from_the_ales_start() -> None:
    from rigctl.tui.session import timecode

    started = "2026-05-01T10:20:30.500+00:00"
    for fps in (25.0, 30000 / 1001):
        start = start_timecode(started, fps)
        assert timecode(started, fps, 0.0) == str(start)
        assert timecode(started, fps, 60.0) == str(start + math.floor(60 * fps))
    assert timecode("", 25.0, 0.0) == "00:00:00:00"


def test_kernel_timecode_fields_become_the_value() -> None:
    from rigctl.drivers.v4l2.device import KernelTimecode

    from rigctl.timecode import TimecodeError

    # V4L2_TC_TYPE_30FPS with V4L2_TC_FLAG_DROPFRAME: 00:00:17;00 is frame 510, 00:00:16;29 frame 509
    assert KernelTimecode(3, 1, 0, 0, 17, 0).to_timecode(29.97) == Timecode(510, 30, True)
    assert KernelTimecode(3, 1, 0, 0, 16, 29).to_timecode(29.97) == Timecode(509, 30, True)
    assert KernelTimecode(2, 0, 1, 0, 0, 0).to_timecode(25.0) == Timecode(90000, 25, False)
    assert KernelTimecode(0, 0, 0, 0, 1, 0).to_timecode(50.0) == Timecode(50, 50, False)  # no type: the format's
    with pytest.raises(TimecodeError, match="dropped label"):
        KernelTimecode(3, 1, 0, 1, 0, 0).to_timecode(29.97)


# ---- EXR -----------------------------------------------------------------------------------------------------
def exr_header(path: Path) -> dict[str, object]:
    return dict(OpenEXR.File(str(path)).header())


def test_exr_export_is_scene_linear_premultiplied_with_attributes(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    fps = 30000 / 1001
    tcs = labels("00:00:59;28", 4, fps)
    folder = write_take(tmp_path / "t", fps, {"r0c0": tcs, "r0c1": tcs})
    out = tmp_path / "seq"
    res = run_cli("take", "export", str(folder), "--out", str(out), "--format", "exr", "--layout", "sequence")
    assert res.returncode == 0, res.stderr
    # one folder per camera, one numbered file per frame set: what NUKE reads as r0c0.######.exr
    assert sorted(p.name for p in (out / "r0c0").iterdir()) == [f"r0c0.{k:06d}.exr" for k in range(4)]
    assert sorted(p.name for p in out.iterdir()) == ["export.json", "r0c0", "r0c1"]  # and the export's record
    for k, tc in enumerate(tcs):
        path = out / "r0c1" / f"r0c1.{k:06d}.exr"
        channels, _ = read_exr(path)
        rgb, a = channels["RGB"], channels["A"]
        # the grey patch: 18 % grey, scene-linear (code value 104 decoded by BT.709's inverse OETF) ...
        patch = rgb[20:28, 28:36]
        expected = ((GREY / 255 + 0.099) / 1.099) ** (1 / 0.45)
        assert np.allclose(patch, expected, atol=1e-5) and abs(expected - 0.18) < 0.0015
        # ... opaque, and the green screen transparent with premultiplied (zero) colour
        assert np.all(a[20:28, 28:36] == 1.0) and np.all(a[:6] == 0.0) and np.all(rgb[:6] == 0.0)
        header = exr_header(path)
        assert np.allclose(header["chromaticities"], REC709_CHROMATICITIES, atol=1e-6)
        assert header["framesPerSecond"] == Fraction(30000, 1001)
        t = header["timeCode"]
        assert (t.hours, t.minutes, t.seconds, t.frame, t.dropFrame) == (*tc.fields(), True)  # type: ignore[attr-defined]
    assert [str(t) for t in tcs] == ["00:00:59;28", "00:00:59;29", "00:01:00;02", "00:01:00;03"]
    # the default layout is as before: DIR/<frame>/<camera>.exr
    res = run_cli("take", "export", str(folder), "--out", str(tmp_path / "flat"), "--format", "exr", "--frames", "1")
    assert res.returncode == 0, res.stderr
    assert [p.relative_to(tmp_path / "flat").as_posix() for p in sorted((tmp_path / "flat").rglob("*.exr"))] == [
        "000001/r0c0.exr",
        "000001/r0c1.exr",
    ]


def test_exr_acescg_option(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    """ACEScg through OpenColorIO: grey stays grey, and a Rec. 709 red is the first column of the published
    Rec. 709 to AP1 matrix (0.6131, 0.0702, 0.0206)."""
    from rigctl.exr import AP1_CHROMATICITIES, to_colour

    assert np.allclose(to_colour(np.array([[1.0, 0, 0]]), "acescg"), [[0.6131, 0.0702, 0.0206]], atol=2e-4)
    folder = write_take(tmp_path / "t", 25.0, {"r0c0": labels("01:00:00:00", 1, 25.0)})
    out = tmp_path / "aces"
    res = run_cli("take", "export", str(folder), "--out", str(out), "--format", "exr", "--colour", "acescg")
    assert res.returncode == 0, res.stderr
    channels, header = read_exr(out / "000000" / "r0c0.exr")
    expected = ((GREY / 255 + 0.099) / 1.099) ** (1 / 0.45)
    assert np.allclose(channels["RGB"][20:28, 28:36], expected, atol=1e-4)
    assert np.allclose(header["chromaticities"], AP1_CHROMATICITIES, atol=1e-6)
    res = run_cli("take", "export", str(folder), "--out", str(out), "--format", "exr", "--colour", "p3")
    assert res.returncode == 2 and "--colour" in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_exr_time_code_at_50_counts_frame_pairs(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    tcs = labels("10:00:00:48", 3, 50.0)
    folder = write_take(tmp_path / "t", 50.0, {"r0c0": tcs})
    res = run_cli(
        "take", "export", str(folder), "--out", str(tmp_path / "o"), "--format", "exr", "--layout", "sequence"
    )
    assert res.returncode == 0, res.stderr
    got = []
    for k in range(3):
        header = exr_header(tmp_path / "o" / "r0c0" / f"r0c0.{k:06d}.exr")
        t = header["timeCode"]
        got.append((t.seconds, t.frame, t.fieldPhase))  # type: ignore[attr-defined]
        assert header["framesPerSecond"] == Fraction(50)
    assert got == [(0, 24, False), (0, 24, True), (1, 0, False)]  # 10:00:00:48, :49, 10:00:01:00


# ---- printing ------------------------------------------------------------------------------------------------
def png_phys(path: Path) -> tuple[int, int, int]:
    """The pHYs chunk of a PNG, read from its bytes: pixels per unit x, y and the unit (1 = metre)."""
    import struct

    data = path.read_bytes()
    at = 8
    while at < len(data):
        length, kind = struct.unpack(">I4s", data[at : at + 8])
        if kind == b"pHYs":
            return struct.unpack(">IIB", data[at + 8 : at + 17])  # type: ignore[return-value]
        at += 12 + length
    raise AssertionError(f"{path}: no pHYs chunk")


@pytest.mark.parametrize(("square_mm", "dpi"), [(75.0, 150.0), (40.0, 300.0), (23.0, 97.0)])
def test_board_png_prints_at_its_size(tmp_path: Path, run_cli, square_mm: float, dpi: float) -> None:  # type: ignore[no-untyped-def]
    import cv2
    from PIL import Image

    from rigctl.board import BoardSpec

    res = run_cli("board", "--out", str(tmp_path / "b"), "--square-mm", f"{square_mm:g}", "--dpi", f"{dpi:g}",
                  "--marker-mm", f"{square_mm * 0.7:g}", "--squares", "5x4")  # fmt: skip
    assert res.returncode == 0, res.stderr
    png = tmp_path / "b.png"
    x, y, unit = png_phys(png)
    assert unit == 1 and x == y and abs(x * 0.0254 - dpi) < 0.02 * dpi
    # the squares as drawn, measured in pixels from the detected corners, printed at the stored resolution
    img = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(BoardSpec.load(tmp_path / "b.yaml").board()).detectBoard(img)
    assert ids is not None and len(ids) == 4 * 3
    pts = corners.reshape(3, 4, 2)
    square_px = (np.diff(pts[..., 0], axis=1).mean() + np.diff(pts[..., 1], axis=0).mean()) / 2
    assert abs(square_px / x * 1000 - square_mm) < 0.02  # mm on paper
    assert Image.open(png).info["dpi"] == pytest.approx((x * 0.0254, x * 0.0254), abs=0.01)


def test_the_recorder_assembles_by_timecode_as_the_reader_does(tmp_path: Path) -> None:
    """Simulated cameras whose frames carry timecode (r0c1's one frame ahead, as a mis-jammed camera would be):
    the recorder's frame sets, sets.csv and ALE follow the timecode, and agree with the reader's."""
    from rigctl.capture.recorder import Recorder, TakePlan
    from rigctl.registry import open_cameras
    from rigctl.rig import load_rig

    rig = load_rig("sim-3x3")
    start = Timecode.parse("09:59:59:20", 25)

    class WithTimecode(CameraWriter):
        def write(self, frame: Frame, frame_set: int = -1) -> None:
            frame.timecode = start + (self.frames + (1 if self.camera == "r0c1" else 0))
            super().write(frame, frame_set)

    devices = open_cameras(rig, ["motion=false", "noise=0"], ["r0c0", "r0c1"])
    rec = Recorder(rig, devices, TakePlan.spread("t", [tmp_path], sorted(devices.cameras)), writer_factory=WithTimecode)
    rec.arm()
    rec.start(10)
    assert rec.wait(timeout_s=60)
    rec.finish()
    reader = TakeReader(tmp_path / "t")
    sets = reader.frame_sets
    assert len(sets) == 11 and [s.number for s in sets if not s.complete(reader.names)] == [0, 10]
    with open(tmp_path / "t" / "sets.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["timecode"] for r in rows] == [str(reader.set_timecode(s)) for s in sets]
    assert rows[0]["timecode"] == "09:59:59:20" and rows[5]["timecode"] == "10:00:00:00"
    assert [r["complete"] for r in rows] == ["0", *["1"] * 9, "0"]
    ale = (tmp_path / "t" / "t.ale").read_text().splitlines()
    data = {r.split("\t")[0]: r.split("\t") for r in ale[ale.index("Data") + 1 :]}
    assert data["t_r0c0"][2:4] == ["09:59:59:20", "10:00:00:05"]
    assert data["t_r0c1"][2:4] == ["09:59:59:21", "10:00:00:06"]
