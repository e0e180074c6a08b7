"""Depth scores see both sides of the silhouette: depth painted on the screen and a subject left without
depth both cost, beside bad 1.0 (which counts only the truth's pixels)."""

from __future__ import annotations

import numpy as np

from rigctl.depth.metrics import score


def subject() -> np.ndarray:
    truth = np.full((40, 60), np.inf, np.float32)
    truth[10:30, 20:40] = 50.0  # 400 subject pixels
    return truth


def test_depth_over_the_whole_screen_is_false_foreground_that_bad_1_does_not_see() -> None:
    truth = subject()
    painted = np.full_like(truth, 50.0)  # the subject's depth everywhere, screen included
    sc = score(painted, truth, np.isfinite(truth))
    assert sc["bad_1.0"] == 0.0  # the old scores call this perfect
    assert sc["false_fg_pct"] == 100.0 * (40 * 60 - 400) / 400 and sc["false_fg_pixels"] == 40 * 60 - 400
    assert sc["missed_fg_pct"] == 0.0


def test_a_one_pixel_halo_and_a_missed_strip_are_counted_on_their_own_side() -> None:
    truth = subject()
    est = np.full_like(truth, np.inf)
    est[9:31, 19:41] = 50.0  # a 1-px halo: 84 pixels
    est[10:30, 20:25] = np.inf  # a strip of the subject with no depth: 100 pixels
    sc = score(est, truth, np.isfinite(truth))
    assert sc["false_fg_pct"] == 100.0 * 84 / 400
    assert sc["missed_fg_pct"] == 100.0 * 100 / 400 == sc["no_estimate_pct"]
    scene = np.ones(truth.shape, bool)
    scene[:10] = False  # a region that is not part of the scene (a burnt-in id) is not counted
    assert score(est, truth, np.isfinite(truth), scene)["false_fg_pct"] == 100.0 * (84 - 22) / 400


def test_an_empty_truth_gives_figures_not_nan() -> None:
    truth = np.full((8, 8), np.inf, np.float32)
    sc = score(np.ones((8, 8), np.float32), truth, np.isfinite(truth))
    assert sc["false_fg_pct"] == 0.0 and sc["false_fg_pixels"] == 64 and sc["missed_fg_pct"] == 0.0
