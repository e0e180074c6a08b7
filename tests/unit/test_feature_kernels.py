"""The compiled features (``feature_kernels.view_features``) are the OpenCV path's (``cost.features`` after
numpy's exposure match over the whole frame) bit for bit: on random and real pictures, parts touching every
edge of the frame and parts inside it, images one pixel wide or high, and with or without the exposure match."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from conftest import SHARED

from rigctl.depth.cost import features
from rigctl.depth.feature_kernels import view_features
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
