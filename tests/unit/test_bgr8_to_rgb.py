"""``pixfmt.bgr8_to_rgb`` (OpenCV's channel swap and a table of v / 255) against its numpy reference: the
same float32 bits for every 8-bit value, in frames of odd sizes, in parts of frames (non-contiguous views,
as the edge tests read them), and for the shapes OpenCV does not take (empty, one channel)."""

from __future__ import annotations

import numpy as np
import pytest

from rigctl.pixfmt import bgr8_to_rgb, bgr8_to_rgb_reference, to_u8


def same(bgr: np.ndarray) -> None:
    fast, ref = bgr8_to_rgb(bgr), bgr8_to_rgb_reference(bgr)
    assert fast.dtype == np.float32 and fast.shape == ref.shape
    assert np.array_equal(fast.view(np.uint32), ref.view(np.uint32))  # bit for bit, not only equal as floats


def test_every_8bit_value_in_every_channel() -> None:
    values = np.arange(256, dtype=np.uint8)
    bgr = np.stack([values, values[::-1], np.roll(values, 77)], axis=1)[None]
    same(bgr)
    rgb = bgr8_to_rgb(bgr)
    assert np.array_equal(rgb[0, :, 2], values / np.float32(255.0))  # B last: the channels are swapped
    assert np.array_equal(to_u8(rgb), bgr)  # still the exact inverse of to_u8 (float RGB to 8-bit BGR)


@pytest.mark.parametrize("shape", [(1, 1, 3), (7, 13, 3), (1080, 1921, 3)])
def test_frames_and_their_parts(shape: tuple[int, ...]) -> None:
    bgr = np.random.default_rng(sum(shape)).integers(0, 256, shape, dtype=np.uint8)
    same(bgr)
    h, w = shape[:2]
    same(bgr[h // 3 : h, w // 4 : w - w // 5])  # a part: rows strided by the frame's width
    same(bgr[::-1, ::2])  # mirrored and strided


@pytest.mark.parametrize("shape", [(0, 5, 3), (4, 0, 3), (3, 4, 1), (3, 4)])
def test_shapes_opencv_does_not_take_fall_back_to_numpy(shape: tuple[int, ...]) -> None:
    bgr = np.zeros(shape, np.uint8)
    assert np.array_equal(bgr8_to_rgb(bgr), bgr8_to_rgb_reference(bgr))
