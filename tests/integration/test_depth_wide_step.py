"""Issue 24: after a sweep at a quarter scale (a range of more than 128 levels: the rig's presenter from
1920x1080 up), the fractional sweep steps by half a pixel over its +-3 px (13 candidates instead of 25). The
parabola and the refinement keep the sub-pixel accuracy: the same scenes over the same wide range, no worse
than the quarter-pixel steps beyond the bench's 0.2 points at 0.2 px and coarser (bad 0.1 is stated, not
held: +1.1 points on the slanted surfaces here, better on the presenter at 1080p). This is the path without
the half-scale band (``costvolume.BAND`` off), which the band is measured against (``test_depth_band.py``)."""

from __future__ import annotations

import numpy as np
import pytest

import rigctl.depth.costvolume as costvolume
from rigctl.depth.estimate import estimate
from rigctl.depth.presets import PRESETS
from rigctl.depth.scenes import SCENES

THRESHOLDS = (0.1, 0.2, 0.5, 1.0, 2.0)


def bad(scene: str, step: float | None, monkeypatch: pytest.MonkeyPatch) -> tuple[dict[float, float], dict]:
    grid = SCENES[scene]((256, 256), 0)
    assert grid.truth is not None and grid.disparity_range is not None
    lo, hi = grid.disparity_range
    monkeypatch.setattr(costvolume, "BAND", False)
    if step is not None:  # else the shipped default
        monkeypatch.setattr(costvolume, "WIDE_STEP", step)
    r = estimate(grid, "r1c1", (lo - 60.0, hi + 60.0), PRESETS["best"], keyer=None)
    truth = grid.truth["r1c1"]
    inner = np.zeros(truth.shape, bool)
    inner[15:-15, 15:-15] = True  # the light-field benchmark's border left out
    inner &= np.isfinite(truth)
    assert np.isfinite(r.disparity[inner]).all()
    err = np.abs(r.disparity - truth)[inner]
    return {t: float(np.mean(~(err <= t)) * 100) for t in THRESHOLDS}, dict(r.stats)


@pytest.mark.parametrize("scene", ["surfaces", "thin"])
def test_half_pixel_steps_after_a_quarter_scale_sweep_keep_the_accuracy(
    scene: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    half, s_half = bad(scene, None, monkeypatch)  # the default first, before the patch
    quarter, s_quarter = bad(scene, costvolume.FRACTION, monkeypatch)
    print(scene, "quarter-pixel steps", quarter, "half-pixel steps", half)
    assert s_quarter["coarse_scale"] == s_half["coarse_scale"] == 0.25
    assert s_quarter["fractional_candidates"] == 25 and s_half["fractional_candidates"] == 13
    assert s_half["fractional_step"] == 0.5
    assert s_half["fractional_sweep_pixel_levels"] * 25 == s_quarter["fractional_sweep_pixel_levels"] * 13
    for t in THRESHOLDS[1:]:
        assert half[t] <= quarter[t] + 0.2, (t, quarter, half)
    assert half[1.0] < 5.0, half  # both are good matches, not equally broken
