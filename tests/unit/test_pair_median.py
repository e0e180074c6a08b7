"""The pairs' median and spread (``pairs.nan_median``, compiled) are the numpy reference's bit for bit, with
NaN and infinities ignored, on one to five layers, and NaN where no layer is finite."""

from __future__ import annotations

import numpy as np
import pytest

from rigctl.depth.pairs import nan_median, nan_median_reference


@pytest.mark.parametrize("layers", [1, 2, 3, 4, 5])
def test_compiled_median_and_spread_are_the_references_bit_for_bit(layers: int) -> None:
    rng = np.random.default_rng(layers)
    stack = (rng.random((layers, 61, 67)) * 300 - 20).astype(np.float32)
    u = rng.random(stack.shape)
    stack[u < 0.2] = np.nan
    stack[(u >= 0.2) & (u < 0.3)] = np.inf
    stack[(u >= 0.3) & (u < 0.33)] = -np.inf
    stack[:, :, :3] = np.nan  # no layer finite
    med, spread = nan_median(stack)
    ref_med, ref_spread = nan_median_reference(stack)
    assert med.dtype == spread.dtype == np.float32
    assert np.array_equal(med, ref_med, equal_nan=True)
    assert np.array_equal(spread, ref_spread, equal_nan=True)
    assert np.isnan(med[:, :3]).all() and np.isnan(spread[:, :3]).all()
    assert np.isfinite(med[:, 3:]).mean() > 0.5


def test_a_known_pixel() -> None:
    stack = np.array([[[4.0]], [[np.nan]], [[1.0]], [[np.inf]], [[2.5]]], np.float32)
    med, spread = nan_median(stack)
    assert med[0, 0] == np.float32(2.5) and spread[0, 0] == np.float32(3.0)
    even = np.array([[[4.0]], [[1.0]], [[2.0]], [[8.0]]], np.float32)
    assert nan_median(even)[0][0, 0] == np.float32(3.0)


def test_no_layers_and_no_pixels() -> None:
    assert np.isnan(nan_median(np.zeros((0, 2, 3), np.float32))[0]).all()
    assert nan_median(np.zeros((3, 0, 4), np.float32))[0].shape == (0, 4)
