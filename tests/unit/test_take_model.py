"""The typed take manifest and the direct frame path: real take folders on disk, written and read back."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from rigctl.depth.grid import FrameImages, TakeGrid
from rigctl.errors import ParameterError, TakeError
from rigctl.interfaces import Frame, FrameFlags
from rigctl.pixfmt import from_rgb, rgb_to_uyvy, to_bgr8, to_gray8, to_rgb, to_u8
from rigctl.take.manifest import Manifest, read_manifest, write_manifest
from rigctl.take.plan import MAX_BUFFERS, check_buffers
from rigctl.take.reader import TakeReader
from rigctl.take.writer import CameraWriter, TakeWriter
from rigctl.timecode import Timecode

W, H = 32, 16

# a manifest as rigctl wrote it before the model existed (the recorder's dict, key for key)
OLD = {
    "spec": 1,
    "take": "T01",
    "status": "complete",
    "started_utc": "2026-05-01T10:20:30.500+00:00",
    "software": {"name": "rigctl", "version": "0.1.0"},
    "rig": {"spec": 1, "name": "sim-3x3"},
    "format": {"width": W, "height": H, "pixel_format": "UYVY", "fps": 25.0, "bytes_per_frame": W * H * 2},
    "timing": {
        "clock": "CLOCK_MONOTONIC",
        "t0_ns": 1000,
        "t1_ns": None,
        "frame_period_ns": 40_000_000,
        "start_timecode": "10:20:30:12",
    },
    "checksum": "crc32",
    "devices": {"description": "simulated", "settings": {"ideal": False, "seed": 3}},
    "cameras": {
        "r0c0": {
            "essence": "cameras/r0c0.essence",
            "index": "cameras/r0c0.index",
            "frames": 3,
            "first_sequence": 0,
            "last_sequence": 2,
            "source_drops": [],
            "error_frames": [],
            "writer_drops": [],
            "not_written": [],
            "ended_early": "signal lost",
        },
    },
    "notes": ["a note"],
    "frame_sets": {
        "count": 3,
        "complete": 3,
        "incomplete": [],
        "skew": {"p50_us": 1.0, "p99_us": 2.0, "max_us": 3.0, "sets": 3},
        "file": "sets.csv",
    },
    "end": {"reason": "frames reached", "message": ""},
}


def write_take(folder: Path, pixel_format: str = "UYVY", timecodes: bool = True) -> list[np.ndarray]:
    """Three frames of a ramp picture per camera, with timecodes; returns the RGB pictures written."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(1)
    pictures = []
    writer = CameraWriter("r0c0", folder / "cameras", 25.0, sync_interval_s=0)
    for i in range(3):
        rgb = rng.random((H, W, 3), dtype=np.float32)
        pictures.append(rgb)
        tc = Timecode.parse("10:20:30:12", 25) + i if timecodes else None
        t = 10**12 + i * 40_000_000
        data = from_rgb(rgb, pixel_format)
        writer.write(Frame("r0c0", 5 + i, t, t + 7, FrameFlags(0), memoryview(data.reshape(-1).data), tc), i)
    writer.close()
    data = dict(OLD)
    # the frames above are sequences 5 to 7: the manifest says so (a reader holds it to the index)
    data["cameras"] = {"r0c0": {**OLD["cameras"]["r0c0"], "first_sequence": 5, "last_sequence": 7}}
    per_pixel = {"UYVY": 2, "BGR3": 3}[pixel_format]
    data["format"] = {**OLD["format"], "pixel_format": pixel_format, "bytes_per_frame": W * H * per_pixel}
    write_manifest(folder, Manifest.model_validate(data))
    return pictures


def test_a_manifest_of_before_the_model_reads_and_writes_back_key_for_key(tmp_path: Path) -> None:
    (tmp_path / "take.yaml").write_text(yaml.safe_dump(OLD, sort_keys=False))
    man = read_manifest(tmp_path)
    assert isinstance(man.timing.start_timecode, Timecode) and str(man.timing.start_timecode) == "10:20:30:12"
    assert man.timing.start_timecode.rate == 25
    assert man.cameras["r0c0"].ended_early == "signal lost" and man.rectification is None
    write_manifest(tmp_path, man)
    again = yaml.safe_load((tmp_path / "take.yaml").read_text())
    assert again == OLD  # the same keys, in no other shape; unset optional sections stay out
    assert list(again) == list(OLD)


def test_verdict_is_set_through_the_model_and_unknown_verdicts_are_refused(tmp_path: Path) -> None:
    (tmp_path / "take.yaml").write_text(yaml.safe_dump(OLD, sort_keys=False))
    man = read_manifest(tmp_path)
    man.mark("circled", "best take")
    write_manifest(tmp_path, man)
    back = read_manifest(tmp_path)
    assert back.verdict == "circled" and back.notes == ["a note", "circled: best take"]
    with pytest.raises(TakeError, match="unknown verdict 'great'"):
        back.mark("great")
    bad = {**OLD, "verdict": "great"}
    (tmp_path / "take.yaml").write_text(yaml.safe_dump(bad, sort_keys=False))
    with pytest.raises(TakeError, match="verdict"):
        read_manifest(tmp_path)


def test_a_bad_start_timecode_or_unknown_section_key_is_refused_naming_the_field(tmp_path: Path) -> None:
    bad = {**OLD, "timing": {**OLD["timing"], "start_timecode": "10:20:30:99"}}
    (tmp_path / "take.yaml").write_text(yaml.safe_dump(bad, sort_keys=False))
    with pytest.raises(TakeError, match=r"take\.yaml.*timing.*start_timecode"):
        read_manifest(tmp_path)
    bad = {**OLD, "end": {"reason": "x", "mesage": ""}}
    (tmp_path / "take.yaml").write_text(yaml.safe_dump(bad, sort_keys=False))
    with pytest.raises(TakeError, match=r"end\.mesage"):
        read_manifest(tmp_path)


@pytest.mark.parametrize("pixel_format", ["UYVY", "YUYV", "BGR3"])
def test_bgr8_is_the_float_path_rounded_bit_for_bit(pixel_format: str) -> None:
    rng = np.random.default_rng(4)
    rgb = rng.random((H, W, 3), dtype=np.float32)
    data = from_rgb(rgb, pixel_format).reshape(-1)
    old = to_u8(to_rgb(data, pixel_format, W, H))  # decode to float, then to 8 bits
    assert np.array_equal(to_bgr8(data, pixel_format, W, H), old)


def test_bt709_not_bt601_and_full_range_grey() -> None:
    # pure red through BT.709 limited range, decoded by BT.601 (OpenCV's UYVY conversion) would come back
    # with green and blue well away from 0; BT.709 gives red back
    red = np.zeros((2, 2, 3), np.float32)
    red[..., 0] = 1.0
    packed = rgb_to_uyvy(red)
    bgr = to_bgr8(packed.reshape(-1), "UYVY", 2, 2).astype(int)
    assert np.abs(bgr[0, 0] - [0, 0, 255]).max() <= 1  # code values are 8-bit: one step of rounding
    bt601 = cv2.cvtColor(packed.reshape(2, 2, 2), cv2.COLOR_YUV2BGR_UYVY).astype(int)
    assert np.abs(bt601[0, 0] - [0, 0, 255]).max() > 10
    white_black = rgb_to_uyvy(np.repeat(np.array([[[1.0] * 3, [0.0] * 3]], np.float32), 2, axis=0))
    assert to_gray8(white_black.reshape(-1), "UYVY", 2, 2).tolist() == [[255, 0], [255, 0]]


def test_to_u8_rounds_half_to_even_and_saturates() -> None:
    x = np.array([[[0.5, 1.5, 2.5]]], np.float32) / 255.0
    assert to_u8(x).tolist() == [[[2, 2, 0]]]  # BGR: 2.5 -> 2, 1.5 -> 2, 0.5 -> 0
    assert to_u8(np.array([[-0.2, 1.7]], np.float32)).tolist() == [[0, 255]]


def test_reader_gives_every_kind_and_opens_each_essence_file_once(tmp_path: Path) -> None:
    pictures = write_take(tmp_path / "t")

    def open_files() -> int:  # this take's (another test's reader, still open in this process, is not counted)
        essence = str(tmp_path / "t")
        return sum(
            1
            for fd in os.listdir("/proc/self/fd")
            if (t := str(_target(fd))).startswith(essence) and "r0c0.essence" in t
        )

    with TakeReader(tmp_path / "t") as reader:
        for i in range(3):
            expected = to_u8(to_rgb(from_rgb(pictures[i], "UYVY").reshape(-1), "UYVY", W, H))
            assert np.array_equal(reader.image("r0c0", i, "bgr8"), expected)
            assert reader.image("r0c0", i, "gray8").shape == (H, W)
            assert np.array_equal(reader.image("r0c0", i, "float"), reader.frame_rgb("r0c0", i))
            assert open_files() == 1
    assert open_files() == 0


def _target(fd: str) -> str:
    try:
        return os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        return ""


def test_take_writer_append_copies_the_source_record_timecode_included(tmp_path: Path) -> None:
    write_take(tmp_path / "src")
    reader = TakeReader(tmp_path / "src")
    out = tmp_path / "out"
    out.mkdir()
    with TakeWriter(out, reader.fps) as writer:
        for i in range(3):
            writer.append("r0c0", np.asarray(reader.image("r0c0", i, "bgr8")), reader.record("r0c0", i))
    src, dst = reader.index["r0c0"], None
    from rigctl.take.index import read_index

    dst, problems = read_index(out / "r0c0.index", (out / "r0c0.essence").stat().st_size)
    assert not problems and len(dst) == 3
    for field in ("sequence", "capture_ns", "host_ns", "flags", "set", "timecode"):
        assert dst[field].tolist() == src[field].tolist(), field
    assert [reader.record("r0c0", i).timecode for i in range(3)] == [
        Timecode.parse("10:20:30:12", 25) + i for i in range(3)
    ]


def test_a_take_without_a_rectification_section_is_not_depth_input(tmp_path: Path) -> None:
    write_take(tmp_path / "t")
    with pytest.raises(TakeError, match=r"not a rectified take.*truth/calibration\.yaml"):
        TakeGrid(tmp_path / "t")


def test_the_grid_gives_the_matcher_8_bit_without_making_float_first(tmp_path: Path) -> None:
    rgb = np.random.default_rng(2).random((H, W, 3), dtype=np.float32)
    packed = from_rgb(rgb, "UYVY").reshape(-1)
    images = FrameImages.captured({"r0c0": packed}, "UYVY", W, H)
    assert np.array_equal(images.bgr8("r0c0"), to_bgr8(packed, "UYVY", W, H))
    assert images._float == {}  # no float picture was made on the way to the matcher
    assert np.array_equal(images["r0c0"], to_rgb(packed, "UYVY", W, H))  # the float picture, unquantised
    assert images.shape() == (H, W)


def test_what_the_grid_made_from_its_pictures_is_let_go_of_and_made_again_alike() -> None:
    rgb = np.random.default_rng(3).random((H, W, 3), dtype=np.float32)
    packed = from_rgb(rgb, "UYVY").reshape(-1)
    images = FrameImages.captured({"r0c0": packed}, "UYVY", W, H)
    bgr, grey, picture = images.bgr8("r0c0").copy(), images.grey("r0c0").copy(), images["r0c0"].copy()
    assert images.made_bytes() == bgr.nbytes + grey.nbytes + picture.nbytes
    images.drop_made()
    assert images.made_bytes() == 0
    assert np.array_equal(images.bgr8("r0c0"), bgr) and np.array_equal(images.grey("r0c0"), grey)
    given = (rgb * 255).astype(np.uint8)
    own = FrameImages({"r0c0": given})
    own.grey("r0c0")
    own.drop_made()
    assert own.bgr8("r0c0") is given and own.made_bytes() == 0  # a picture given as 8 bits is kept


def test_a_grey_keeps_no_float_picture_and_the_last_picture_can_be_let_go_of() -> None:
    """Issue 24: the greys the search reads are kept, the float pictures made for them are not, and the last
    float picture asked for is let go of before the search (``forget_last``); each made again alike."""
    rgb = np.random.default_rng(4).random((H, W, 3), dtype=np.float32)
    images = FrameImages({n: (rgb * 255).astype(np.uint8) for n in ("r0c0", "r0c1")})
    last = images["r0c0"]
    picture = last.copy()
    grey = images.grey("r0c1").copy()
    assert images.made_bytes() == picture.nbytes + grey.nbytes
    assert images["r0c0"] is last  # still the last picture: r0c1's, made for its grey, was not kept
    assert images.grey("r0c0").nbytes == grey.nbytes  # from the last picture, which stays
    assert images.made_bytes() == picture.nbytes + 2 * grey.nbytes
    images.forget_last()
    assert images.made_bytes() == 2 * grey.nbytes
    assert np.array_equal(images["r0c0"], picture) and np.array_equal(images.grey("r0c1"), grey)


def test_a_fresh_picture_is_a_new_array_kept_by_no_one() -> None:
    """Issue 24, the write's peak: the soft key takes its picture through ``fresh``, a new array each call with
    the picture's values, which the grid does not keep (not as its last picture either) and which the caller
    may change without changing the grid's (a given float picture is copied)."""
    rgb = np.random.default_rng(5).random((H, W, 3), dtype=np.float32)
    packed = from_rgb(rgb, "UYVY").reshape(-1)
    for images in (
        FrameImages({"r0c0": (rgb * 255).astype(np.uint8)}),
        FrameImages({"r0c0": rgb.copy()}),
        FrameImages.captured({"r0c0": packed}, "UYVY", W, H),
    ):
        a, b = images.fresh("r0c0"), images.fresh("r0c0")
        assert images.made_bytes() == 0  # neither kept (a read as a mapping keeps the last picture)
        assert a is not b and not np.shares_memory(a, b)
        assert np.array_equal(a, b) and np.array_equal(a, images["r0c0"])
        a[...] = -1.0
        assert np.array_equal(b, images["r0c0"]) and not np.shares_memory(b, images["r0c0"])


@pytest.mark.parametrize("pixel_format", ["UYVY", "v210", "BGR3", "8-bit given", "float given"])
def test_greys_beyond_the_budget_are_made_again_row_by_row_alike(
    pixel_format: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 24: the greys are kept up to ``GREY_KEEP_BYTES`` (nine of 3840x2160 are 0.28 GiB at the
    estimates' peak); beyond it a grey, or any run of its rows, is made again from the picture's own rows, in
    bands, with the same bits as the whole picture's grey, for every way a picture comes."""
    import rigctl.depth.grid as grid_module

    h, w = 37, 96  # bands of 5 rows leave a part of one at the end
    rgb = np.random.default_rng(7).random((h, w, 3), dtype=np.float32)
    if pixel_format == "8-bit given":
        images = FrameImages({"a": to_u8(rgb), "b": to_u8(rgb[::-1])})
    elif pixel_format == "float given":
        images = FrameImages({"a": rgb, "b": rgb[::-1].copy()})
    else:
        images = FrameImages.captured(
            {"a": from_rgb(rgb, pixel_format).reshape(-1), "b": from_rgb(rgb[::-1], pixel_format).reshape(-1)},
            pixel_format,
            w,
            h,
        )
    whole = {n: grid_module.grey(images[n]) for n in ("a", "b")}
    images.forget_last()
    monkeypatch.setattr(grid_module, "GREY_BAND_ROWS", 5)
    monkeypatch.setattr(grid_module, "GREY_KEEP_BYTES", whole["a"].nbytes)  # room for one grey
    for a, b in ((0, h), (3, 4), (0, 12), (30, h), (10, 10)):
        assert np.array_equal(images.grey_rows("b", a, b), whole["b"][a:b])
    assert np.array_equal(images.grey("a"), whole["a"]) and np.array_equal(images.grey("b"), whole["b"])
    assert images.made_bytes() == whole["a"].nbytes  # the first fitted, the second is made on each read
    assert images.grey("a") is images.grey("a") and images.grey("b") is not images.grey("b")
    assert np.array_equal(images.grey_rows("a", 3, 9), whole["a"][3:9])


def test_a_frame_pool_is_bounded_by_count_and_memory() -> None:
    """``--buffers 999999999`` was an ENOMEM traceback from the pool's mmap; now one line before allocating."""
    assert check_buffers(2, 1 << 20, 9, memory=64 << 30) == 2
    assert check_buffers(MAX_BUFFERS, 1 << 20, 9, memory=64 << 30) == MAX_BUFFERS
    with pytest.raises(ParameterError, match=r"--buffers must be 2 to 1024 .*got 1025"):
        check_buffers(MAX_BUFFERS + 1, 1 << 20, 9, memory=64 << 30)
    with pytest.raises(ParameterError, match=r"got 1$"):
        check_buffers(1, 1 << 20, 9)
    # nine UHD cameras (16.6 MB frames) on a 16 GB machine: 53 buffers each fill half of its memory
    with pytest.raises(ParameterError, match=r"2 to 53 \(the pools of 9 camera\(s\) of 16.6 MB frames .*16.0 GB"):
        check_buffers(54, 3840 * 2160 * 2, 9, memory=16 * 10**9)
    assert check_buffers(53, 3840 * 2160 * 2, 9, memory=16 * 10**9) == 53
