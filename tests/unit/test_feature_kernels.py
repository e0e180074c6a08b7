"""The compiled features (``feature_kernels.view_features``) are the OpenCV path's (``cost.features`` after
numpy's exposure match over the whole frame) bit for bit: on random and real pictures, parts touching every
edge of the frame and parts inside it, images one pixel wide or high, and with or without the exposure match."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from conftest import SHARED

from rigctl.depth.cost import features
from rigctl.depth.feature_kernels import features_of_levels, view_features, view_levels
from rigctl.depth.grid import grey


def _reference(g: np.ndarray, part: tuple[int, int, int, int], exposure: tuple[float, float] | None) -> np.ndarray:
    if exposure is not None:
        g = g * np.float32(exposure[0]) + np.float32(exposure[1])
    return features(g, part)


def _parts(h: int, w: int) -> list[tuple[int, int, int, int]]:
    inner = (min(1, h - 1), max(min(1, h - 1) + 1, h - 1), min(2, w - 1), max(min(2, w - 1) + 1, w - 2))
    return [(0, h, 0, w), inner, (0, 1, 0, w), (h - 1, h, 0, w), (0, h, w - 1, w), (0, h, 0, 1)]


@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (6, 1), (2, 2), (7, 9), (64, 97)])
@pytest.mark.parametrize("exposure", [None, (1.37, -0.021), (1.0, 0.0)])
def test_compiled_features_are_the_opencv_paths_bit_for_bit(
    shape: tuple[int, int], exposure: tuple[float, float] | None
) -> None:
    g = np.random.default_rng(sum(shape)).random(shape, np.float32)
    for part in _parts(*shape):
        ref = _reference(g, part, exposure)
        got = view_features(g, part, exposure=exposure)
        assert got.shape == ref.shape == (part[1] - part[0], part[3] - part[2], 3)
        assert np.array_equal(got, ref), (shape, part, exposure)


def test_on_a_real_picture_into_a_stack_place() -> None:
    bgr = cv2.imread(str(SHARED / "data" / "hci-training" / "cotton" / "input_Cam040.png"), cv2.IMREAD_COLOR)
    assert bgr is not None
    g = grey(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB).astype(np.float32) / np.float32(255))
    h, w = g.shape
    stack = np.full((2, 200, 300, 3), np.nan, np.float32)
    for i, (part, exposure) in enumerate((((0, 200, w - 300, w), (0.93, 0.012)), ((h - 200, h, 0, 300), None))):
        view_features(g, part, out=stack[i], exposure=exposure)
        assert np.array_equal(stack[i], _reference(g, part, exposure))
    assert np.isfinite(stack).all()  # every place written


def test_the_derivatives_see_the_exposure_match() -> None:
    # a ramp: matched by gain 2, the derivatives double (a kernel that matched only the intensity would not)
    g = np.tile(np.arange(8, dtype=np.float32), (4, 1)) / np.float32(8)
    plain = view_features(g, (0, 4, 0, 8))
    matched = view_features(g, (0, 4, 0, 8), exposure=(2.0, 0.0))
    assert np.array_equal(matched[..., 1], 2 * plain[..., 1])
    assert plain[1, 3, 1] == pytest.approx(0.125)


@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (6, 1), (2, 2), (7, 9), (64, 97)])
@pytest.mark.parametrize("exposure", [None, (1.37, -0.021)])
def test_levels_make_the_features_bit_for_bit(shape: tuple[int, int], exposure: tuple[float, float] | None) -> None:
    """Issue 24: the cost volume keeps each view's part as levels (its intensity with one pixel around it, the
    frame's edges replicated) and the kernels make the derivatives from them; ``features_of_levels`` (what the
    reference paths read) is ``view_features`` bit for bit, at every edge of the frame and inside it."""
    g = np.random.default_rng(sum(shape) + 1).random(shape, np.float32)
    for part in _parts(*shape):
        levels = view_levels(g, part, exposure=exposure)
        assert levels.shape == (part[1] - part[0] + 2, part[3] - part[2] + 2)
        want = view_features(g, part, exposure=exposure)
        assert np.array_equal(features_of_levels(levels).view(np.uint32), want.view(np.uint32)), (shape, part)


def test_the_kernels_sample_the_levels_as_they_sampled_the_features() -> None:
    """``cost_kernels.sample3`` makes a sample's three channels from the levels: the bilinear mix of the four
    corners' ``view_features``, in the same order, on a real picture and at the part's clamped edges."""
    from numba import njit

    from rigctl.depth.cost_kernels import sample3

    @njit(cache=False)
    def samples(levels: np.ndarray, points: np.ndarray, out: np.ndarray) -> None:
        hh, ww = levels.shape[1] - 2, levels.shape[2] - 2
        for k in range(points.shape[0]):
            my, mx = points[k, 0], points[k, 1]
            by, bx = np.floor(my), np.floor(mx)
            ey, ex = my - by, mx - bx
            ya, yb = min(max(int(by), 0), hh - 1), min(max(int(by) + 1, 0), hh - 1)
            xa, xb = min(max(int(bx), 0), ww - 1), min(max(int(bx) + 1, 0), ww - 1)
            one = np.float32(1.0)
            w = ((one - ey) * (one - ex), (one - ey) * ex, ey * (one - ex), ey * ex)
            out[k, 0], out[k, 1], out[k, 2] = sample3(levels, 0, ya, yb, xa, xb, w[0], w[1], w[2], w[3])

    bgr = cv2.imread(str(SHARED / "data" / "hci-training" / "cotton" / "input_Cam040.png"), cv2.IMREAD_COLOR)
    g = grey(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB).astype(np.float32) / np.float32(255))
    h = g.shape[0]
    part = (h - 120, h, 3, 163)  # at the frame's bottom edge; samples beyond the part clamp to its edge
    feats = view_features(g, part, exposure=(0.93, 0.012))
    levels = view_levels(g, part, exposure=(0.93, 0.012))[None]
    rng = np.random.default_rng(9)
    points = np.concatenate([rng.uniform(-2, 122, (4000, 1)), rng.uniform(-2, 162, (4000, 1))], 1).astype(np.float32)
    got = np.empty((len(points), 3), np.float32)
    samples(levels, points, got)
    want = np.empty_like(got)
    for k, (my, mx) in enumerate(points):  # the features' bilinear mix as the kernels did it before
        by, bx = np.floor(my), np.floor(mx)
        ey, ex = np.float32(my - by), np.float32(mx - bx)
        ya, yb = min(max(int(by), 0), 119), min(max(int(by) + 1, 0), 119)
        xa, xb = min(max(int(bx), 0), 159), min(max(int(bx) + 1, 0), 159)
        one = np.float32(1.0)
        w00, w01, w10, w11 = (one - ey) * (one - ex), (one - ey) * ex, ey * (one - ex), ey * ex
        s = feats[ya, xa] * w00 + feats[ya, xb] * w01
        s += feats[yb, xa] * w10
        s += feats[yb, xb] * w11
        want[k] = s
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
