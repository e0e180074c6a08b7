"""The soft key's wide blurs start from the weighted values shrunk by an area average (``LocalMean.shrunk``).
Issue 24: where the scale divides the frame it is made in bands of whole blocks, never the frame's weighted
values at once; the values are OpenCV's over the frame, bit for bit."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from rigctl import local_mean
from rigctl.local_mean import LocalMean, with_ones


@pytest.mark.parametrize("rows", [1, 40, 128, 10_000])
@pytest.mark.parametrize("shape", [(288, 384), (291, 385)])  # divided by 3, 4 and 16; and by none of them
def test_the_shrunk_weighted_values_in_bands_are_the_frames(
    monkeypatch: pytest.MonkeyPatch, rows: int, shape: tuple[int, int]
) -> None:
    rng = np.random.default_rng(rows)
    values = with_ones(rng.random((*shape, 3), dtype=np.float32) * np.float32(1.5) - np.float32(0.2))
    weight = (rng.random(shape) > 0.6).astype(np.float32)
    mean = LocalMean(values, weight, (4.0, 16.0, 64.0))
    made = []
    real = mean.weighted
    monkeypatch.setattr(mean, "weighted", lambda box=None: made.append(box) or real(box))
    monkeypatch.setattr(local_mean, "SHRINK_ROWS", rows)
    h, w = shape
    for scale in (3, 4, 16):
        made.clear()
        whole = cv2.resize(real(), (w // scale, h // scale), interpolation=cv2.INTER_AREA)
        got = mean.shrunk(scale)
        assert got.dtype == np.float32 and got.shape == whole.shape
        assert np.array_equal(got.view(np.uint32), whole.view(np.uint32))
        if h % scale or w % scale:
            assert made == [None]  # over the frame at once, as before
        else:
            assert None not in made and all((b[1] - b[0]) % scale == 0 for b in made)
            assert len(made) == -(-h // (-(-rows // scale) * scale))  # bands of whole blocks
