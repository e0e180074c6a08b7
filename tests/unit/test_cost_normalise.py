"""The plane sweep's cost (``cost.py``): issue 24's forms against the forms before. ``cost.normalise_part``,
the locally normalised intensity of a part of a grey made from that part and the window's reach around it,
against ``cost.normalise`` of the whole grey cropped (what the plane sweep, the pair fusion's referee and the
cost volume's texture used before); the referee's box sums one view at a time against four as channels.

Tolerance: none on 8-bit pictures (OpenCV's box sums of float run in double, which holds the sums of 8-bit
greys and their squares exactly, wherever on the row a sum starts); on arbitrary float greys within 1e-6
(the double sums round differently, then round to float32)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from conftest import SHARED

from rigctl.depth.cost import normalise, normalise_part
from rigctl.depth.grid import grey

PICTURES = ["hci-training/cotton/input_Cam040.png", "opencv-stereo-chessboard/left01.jpg"]


def parts(shape: tuple[int, int], rng: np.random.Generator, n: int) -> list[tuple[int, int, int, int]]:
    """Random parts, and the frame's corners and edges (where the reflected border is the frame's)."""
    h, w = shape
    out = [(0, h, 0, w), (0, 5, 0, 5), (h - 5, h, w - 5, w), (0, h, w - 1, w), (h // 2, h // 2 + 1, 0, w)]
    for _ in range(n):
        y0, x0 = int(rng.integers(0, h - 1)), int(rng.integers(0, w - 1))
        out.append((y0, int(rng.integers(y0 + 1, h + 1)), x0, int(rng.integers(x0 + 1, w + 1))))
    return out


@pytest.mark.parametrize("name", PICTURES)
def test_part_of_an_8bit_picture_is_bit_exact(name: str) -> None:
    bgr = cv2.imread(str(SHARED / "data" / name), cv2.IMREAD_COLOR)
    assert bgr is not None, f"cannot read {SHARED / 'data' / name}"
    g = grey(bgr[..., ::-1].astype(np.float32) / np.float32(255.0))
    whole_norm, whole_std = normalise(g)
    for y0, y1, x0, x1 in parts(g.shape, np.random.default_rng(7), 40):
        norm, std = normalise_part(g, (y0, y1, x0, x1))
        assert norm.shape == (y1 - y0, x1 - x0) and norm.flags.c_contiguous and std.flags.c_contiguous
        assert np.array_equal(norm, whole_norm[y0:y1, x0:x1]), (y0, y1, x0, x1)
        assert np.array_equal(std, whole_std[y0:y1, x0:x1]), (y0, y1, x0, x1)


def test_part_of_a_float_grey_within_rounding() -> None:
    rng = np.random.default_rng(3)
    g = (rng.random((180, 240)) ** 3).astype(np.float32)  # dark pixels beside bright ones: inexact sums
    whole_norm, whole_std = normalise(g)
    for y0, y1, x0, x1 in parts(g.shape, rng, 40):
        norm, std = normalise_part(g, (y0, y1, x0, x1))
        np.testing.assert_allclose(norm, whole_norm[y0:y1, x0:x1], rtol=0, atol=1e-6)
        np.testing.assert_allclose(std, whole_std[y0:y1, x0:x1], rtol=0, atol=1e-6)


def test_a_part_that_ignores_its_surroundings_would_be_caught() -> None:
    """The check above can fail: a part normalised alone (its own edges reflected) differs from the frame's."""
    bgr = cv2.imread(str(SHARED / "data" / PICTURES[0]), cv2.IMREAD_COLOR)
    g = grey(bgr[..., ::-1].astype(np.float32) / np.float32(255.0))
    alone, _ = normalise(np.ascontiguousarray(g[100:200, 100:200]))
    assert not np.array_equal(alone, normalise(g)[0][100:200, 100:200])


def test_one_view_at_a_time_is_the_four_channel_box_filter() -> None:
    """``SweepLevel.costs_where`` aggregates one view at a time (it took four views as the four channels of one
    image): OpenCV sums each channel on its own, so the sums are the same bits, here on sparse differences
    of the sizes and windows the referee uses, the crop's edges included."""
    rng = np.random.default_rng(5)
    for shape, win in (((60, 90), 3), ((257, 131), 5), ((1080, 700), 7)):
        dense = np.zeros((*shape, 4), np.float32)
        mask = rng.random(shape) < 0.2
        dense[mask] = (rng.random((int(mask.sum()), 4)) * 1.5).astype(np.float32)
        four = cv2.boxFilter(dense, -1, (win, win), borderType=cv2.BORDER_REFLECT)
        for c in range(4):
            one = cv2.boxFilter(np.ascontiguousarray(dense[..., c]), -1, (win, win), borderType=cv2.BORDER_REFLECT)
            assert np.array_equal(one.view(np.uint32), np.ascontiguousarray(four[..., c]).view(np.uint32))
