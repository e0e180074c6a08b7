"""The alpha-matting benchmark's measures on the edge band: each sees the fault it is meant for."""

from __future__ import annotations

import numpy as np

from rigctl.depth.matte_scores import edge_band, matte_scores


def soft_disc(h: int = 64, w: int = 64, r: float = 18.0, ss: int = 8) -> np.ndarray:
    yy, xx = (np.mgrid[0 : h * ss, 0 : w * ss] + 0.5) / ss
    inside = (yy - 32.2) ** 2 + (xx - 31.7) ** 2 < r * r
    return inside.reshape(h, ss, w, ss).mean(axis=(1, 3)).astype(np.float32)


def test_a_perfect_key_scores_zero_and_the_band_is_the_silhouette() -> None:
    truth = soft_disc()
    sc = matte_scores(truth, truth)
    assert sc["sad_k"] == sc["mse"] == sc["gradient_k"] == sc["connectivity_k"] == 0.0
    band = edge_band(truth, 3)
    assert band[32, 32 - 18] and not band[32, 32] and not band[2, 2]
    assert sc["band_pixels"] == int(band.sum())


def test_sad_and_mse_grow_with_the_error_and_a_hard_key_loses_the_gradient() -> None:
    truth = soft_disc()
    hard = (truth >= 0.5).astype(np.float32)  # the same silhouette with no soft edge
    grown = (soft_disc(r=19.5) > 0).astype(np.float32)  # a 1.5-px halo
    s_hard, s_grown = matte_scores(hard, truth), matte_scores(grown, truth)
    assert 0 < s_hard["sad_k"] < s_grown["sad_k"] and 0 < s_hard["mse"] < s_grown["mse"]
    assert s_hard["gradient_k"] > 0


def test_connectivity_sees_a_strand_cut_off_from_the_subject() -> None:
    truth = np.zeros((40, 60), np.float32)
    truth[10:30, 5:25] = 1.0
    truth[19:21, 25:55] = 0.6  # a soft strand attached to the body
    attached = truth.copy()
    cut = truth.copy()
    cut[19:21, 25:27] = 0.0  # the same strand, two pixels from the body missing
    a, c = matte_scores(attached * 0.95 + 0.05 * truth, truth), matte_scores(cut, truth)
    assert c["connectivity_k"] > a["connectivity_k"]
    assert c["connectivity_k"] > 0
