"""Pixel formats, PFM files and the burnt-in frame ids round-trip exactly, and refuse what is wrong."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from rigctl.simulators import burnin

from rigctl.errors import TakeError
from rigctl.pfm import read_pfm, write_pfm
from rigctl.pixfmt import from_rgb, luma, rgb_to_uyvy, to_rgb, uyvy_to_rgb


def test_uyvy_round_trip_within_quantisation() -> None:
    rng = np.random.default_rng(0)
    # smooth colours (4:2:2 halves chroma resolution, so test on pairs with equal colour)
    rgb = np.repeat(rng.uniform(0, 1, (32, 16, 3)).astype(np.float32), 2, axis=1)
    back = uyvy_to_rgb(rgb_to_uyvy(rgb))
    assert np.abs(back - rgb).max() < 2.5 / 255
    yuyv = from_rgb(rgb, "YUYV")
    assert np.abs(to_rgb(yuyv, "YUYV", 32, 32) - rgb).max() < 2.5 / 255


def test_bt709_reference_colours() -> None:
    # BT.709 limited range: white Y=235, black Y=16, pure red Y = 16 + 219 * 0.2126 = 62.6
    colours = np.array([[[1, 1, 1], [1, 1, 1], [0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0]]], dtype=np.float32)
    packed = rgb_to_uyvy(colours)
    assert list(luma(packed)[0]) == [235, 235, 16, 16, 63, 63]
    assert packed[0, 0] == 128 and packed[0, 2] == 128  # neutral chroma for white
    assert packed[0, 10] == 240  # Cr of pure red: 128 + 224 * 0.5


def test_odd_width_is_refused() -> None:
    from rigctl.errors import ParameterError

    with pytest.raises(ParameterError, match="even width"):
        rgb_to_uyvy(np.zeros((2, 3, 3), dtype=np.float32))


def test_pfm_round_trip_keeps_inf_and_orientation(tmp_path: Path) -> None:
    img = np.arange(12, dtype=np.float32).reshape(3, 4)
    img[0, 0] = np.inf
    write_pfm(tmp_path / "d.pfm", img)
    raw = (tmp_path / "d.pfm").read_bytes()
    assert raw.startswith(b"Pf\n4 3\n-1.0\n")
    # rows are stored bottom to top: the first stored row is the image's last
    assert np.frombuffer(raw[-16:], "<f4").tolist() == img[0].tolist()
    back = read_pfm(tmp_path / "d.pfm")
    assert np.array_equal(back, img)


def test_truncated_pfm_names_file_and_offset(tmp_path: Path) -> None:
    write_pfm(tmp_path / "d.pfm", np.zeros((3, 4), np.float32))
    data = (tmp_path / "d.pfm").read_bytes()
    (tmp_path / "d.pfm").write_bytes(data[:-5])
    with pytest.raises(TakeError, match=r"d\.pfm: byte 12: expected 48 bytes"):
        read_pfm(tmp_path / "d.pfm")


@given(st.integers(0, 255), st.integers(0, 2**24 - 1), st.integers(0, 2**24 - 1), st.sampled_from([960, 1920, 3840]))
def test_burnt_id_round_trip(camera: int, seq: int, scene: int, width: int) -> None:
    packed = np.full((40, width * 2), 128, dtype=np.uint8)
    burnin.burn(packed, width, camera, seq, scene)
    got = burnin.read(packed, width)
    assert got == burnin.BurntId(camera, seq, scene)


def test_burnt_id_damage_is_detected() -> None:
    packed = np.full((40, 1920), 128, dtype=np.uint8)
    burnin.burn(packed, 960, 4, 1234, 99)
    packed[:3, 1 + 2 * 3 * 9 : 2 * 3 * 10] ^= 0xFF  # flip one block
    assert burnin.read(packed, 960) is None


BAD_PFMS = {  # file name: (how it is made, what the one-line error says)
    "zero": (lambda p: p.symlink_to("/dev/zero"), "not a regular file"),
    "fifo": (os.mkfifo, "not a regular file"),  # nobody writes: an open waiting for a writer would hang
    "huge": (lambda p: p.write_bytes(b"Pf\n100000 100000\n-1.0\n" + bytes(64)), "PFM header: size 100000x100000"),
    "scale0": (lambda p: p.write_bytes(b"Pf\n2 1\n0\n" + bytes(8)), "PFM header: scale"),
    "scalenan": (lambda p: p.write_bytes(b"Pf\n2 1\nnan\n" + bytes(8)), "PFM header: scale"),
    "negative": (lambda p: p.write_bytes(b"Pf\n-2 1\n-1.0\n" + bytes(8)), "PFM header: size -2x1"),
}


@pytest.mark.parametrize("name", list(BAD_PFMS))
def test_a_pfm_that_is_a_device_or_lies_about_its_size_is_refused_before_reading(tmp_path: Path, name: str) -> None:
    """A disparity file linked to /dev/zero once read until the machine ran out of memory: only a regular
    file whose size matches its header is read."""
    make, says = BAD_PFMS[name]
    path = tmp_path / f"{name}.pfm"
    make(path)
    with pytest.raises(TakeError, match=re.escape(f"{name}.pfm: {says}")):
        read_pfm(path)


def test_a_regular_file_is_read_through_a_blocking_descriptor(tmp_path: Path) -> None:
    """open_regular opens without blocking (a FIFO must not hang it) but hands back a blocking descriptor: on a
    9p shared folder a non-blocking read returns one message's worth of bytes, and frames read short."""
    from rigctl.regular import open_regular

    f = tmp_path / "frame.bin"
    f.write_bytes(b"x" * 4096)
    fd, size = open_regular(f)
    try:
        assert size == 4096 and os.get_blocking(fd)
    finally:
        os.close(fd)


def test_a_link_to_nothing_is_named_as_one(tmp_path: Path) -> None:
    """A hostile-user review: a dangling symbolic link (sets.csv pointing at a file that is gone) was
    reported as "no such frame-set file", though a file is listed at that name; the link and where it points
    are named. A name with nothing at it still reads "no such"."""
    from rigctl.regular import read_regular

    link = tmp_path / "sets.csv"
    link.symlink_to(tmp_path / "gone" / "sets.csv")
    with pytest.raises(TakeError) as err:
        read_regular(link, 1000, TakeError, "frame-set file")
    assert (
        str(err.value)
        == f"{link}: frame-set file is a symbolic link to '{tmp_path}/gone/sets.csv', which leads to no file"
    )
    with pytest.raises(TakeError, match=r"log.csv: no such frame-set file$"):
        read_regular(tmp_path / "log.csv", 1000, TakeError, "frame-set file")
