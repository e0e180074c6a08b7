"""The ``best`` preset's choice between its two candidates (``volume_engine.pick_pairs``) compares the two
aggregated costs instead of taking ``np.argmin`` over their stack: the same choice on every pixel, NaN, ties
and signed zeros included, and the same result on a scene whose pairs and sweep disagree."""

from __future__ import annotations

import numpy as np

from rigctl.depth.costvolume import Aggregator, MatchViews, VolumeParams
from rigctl.depth.volume_engine import pick_pairs, second_lower


def test_second_lower_is_argmin_of_the_two() -> None:
    rng = np.random.default_rng(0)
    shape = (40, 50)
    first = rng.random(shape).astype(np.float32)
    second = rng.random(shape).astype(np.float32)
    second[:, :5] = first[:, :5]  # ties: the first
    first[0, :10], second[0, 5:15] = np.nan, np.nan  # NaN on either side and on both
    first[1, :3], second[1, :3] = np.float32(0.0), np.float32(-0.0)
    first[2, :3], second[2, :3] = np.inf, np.float32(3.0)
    expected = np.argmin(np.stack([first, second]), axis=0) == 1
    got = second_lower(first, second)
    assert np.array_equal(got, expected)
    assert got.any() and not got.all()


def test_pick_pairs_is_the_stacked_argmins_choice() -> None:
    rng = np.random.default_rng(5)
    base = rng.random((48, 80, 3)).astype(np.float32)
    images = {"a": base, "b": np.roll(base, -4, axis=1), "c": np.roll(base, 4, axis=1), "d": np.roll(base, 4, axis=0)}
    views = MatchViews(images, "a", {"b": (1.0, 0.0), "c": (-1.0, 0.0), "d": (0.0, -1.0)}, (0, 48, 0, 80))
    p = VolumeParams(keep=2)
    d = np.full((48, 80), 4.0, np.float32) + rng.normal(0, 0.3, (48, 80)).astype(np.float32)
    pairs = np.full((48, 80), 4.0, np.float32) + rng.normal(0, 0.3, (48, 80)).astype(np.float32)
    pairs[:, :20] = 9.0  # a stretch where they disagree on the match: the pixel's own cost decides
    got = pick_pairs(views, d, pairs, p)
    agg = Aggregator(views.guide, p.radius, p.eps)
    costs = np.stack([agg(views.costs(c, p.window, p.keep)) for c in (d, pairs)])
    at_pixel = views.costs(pairs, 1, p.keep) < views.costs(d, 1, p.keep)
    expected = np.where(np.abs(pairs - d) > 1.0, at_pixel, np.argmin(costs, axis=0) == 1)
    assert np.array_equal(got, expected)
    assert got[:, 25:].any() and not got[:, 25:].all()  # both candidates win somewhere they agree


def _fill_by_hand(disp: np.ndarray, holes: np.ndarray) -> np.ndarray:
    out = disp.copy()
    for y, x in zip(*np.nonzero(holes), strict=True):
        ok = np.isfinite(disp[y]) & ~holes[y]
        left = [disp[y, i] for i in range(x - 1, -1, -1) if ok[i]][:1]
        right = [disp[y, i] for i in range(x + 1, disp.shape[1]) if ok[i]][:1]
        out[y, x] = min(left + right, default=np.inf)
    return out


def test_fill_from_background_takes_the_farther_side_on_rows_with_holes_only() -> None:
    from rigctl.depth.pair_fusion import fill_from_background

    rng = np.random.default_rng(2)
    disp = (rng.random((30, 40)) * 50 + 100).astype(np.float32)
    disp[rng.random(disp.shape) < 0.1] = np.inf  # no estimate: neither a hole nor a source
    holes = np.zeros(disp.shape, bool)
    holes[3:9, 10:20] = True
    holes[12, :] = True  # a whole row: nothing to take
    holes[20, :5] = True  # at the row's start: only the right side
    holes[25, 35:] = True  # at its end: only the left
    got = fill_from_background(disp, holes)
    assert np.array_equal(got, _fill_by_hand(disp, holes))
    assert np.array_equal(got[~holes], disp[~holes])  # rows without holes untouched
    assert np.isinf(got[12]).all() and np.isfinite(got[3:9, 10:20]).all()
    assert np.array_equal(fill_from_background(disp, np.zeros_like(holes)), disp)
