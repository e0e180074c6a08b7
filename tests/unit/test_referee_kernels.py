"""The pair fusion's compiled referee (``rigctl/depth/referee_kernels.py``) against the OpenCV and numpy form it
replaces (``SweepLevel.costs_where`` with ``cost.COMPILED`` off), on a textured scene with slanted and curved
surfaces: an off-centre crop, windows of 1 to 7 px whose reflection at the crop's edges matters, candidate maps
that reach outside the views, and query pixels along every edge of the crop.

Tolerance: the same query pixels are INVALID (the query's own sample outside the frame); elsewhere within 1e-5
(costs run 0..1.5: the window's sums and the kept views' mean are added in another order), and the candidate
the referee picks is the same wherever the reference's best two are more than that apart."""

from __future__ import annotations

import numpy as np
import pytest

import rigctl.depth.cost as cost
from rigctl.depth.cost import INVALID_COST, SweepLevel
from rigctl.depth.scenes import surfaces


def referee(level: SweepLevel, cands: list[np.ndarray], where: np.ndarray, win: int, keep: int, compiled: bool):
    old = cost.COMPILED
    cost.COMPILED = compiled
    try:
        return level.costs_where(cands, where, win, keep)
    finally:
        cost.COMPILED = old


@pytest.mark.parametrize("win,keep", [(1, 4), (3, 4), (3, 8), (5, 2), (7, 3)])
def test_the_compiled_referee_matches_the_reference(win: int, keep: int) -> None:
    grid = surfaces((96, 128))
    assert grid.disparity_range is not None
    lo, hi = grid.disparity_range
    box = (7, 90, 5, 121)
    views = [n for n in grid.names if n != "r1c1"]
    level = SweepLevel(grid, "r1c1", views, 1.0, box, (lo - 40.0, hi + 40.0))
    shape = (box[1] - box[0], box[3] - box[2])
    rng = np.random.default_rng(3)
    cands = [
        rng.uniform(lo, hi, shape).astype(np.float32),
        (rng.uniform(lo, hi, shape) + 0.37).astype(np.float32),
        np.full(shape, hi + 35.0, np.float32) + rng.uniform(-0.5, 0.5, shape).astype(np.float32),  # outside views
        np.full(shape, np.float32(0.5 * (lo + hi))),
        np.full(shape, 500.0, np.float32),  # outside every view: INVALID
    ]
    where = rng.random(shape) < 0.3
    where[0, :] = where[-1, :] = where[:, 0] = where[:, -1] = True  # the window reflected at every edge
    fast = referee(level, cands, where, win, keep, True)
    want = referee(level, cands, where, win, keep, False)
    assert fast.shape == want.shape == (len(cands), int(where.sum()))
    invalid = want >= INVALID_COST * 0.5
    assert np.array_equal(fast >= INVALID_COST * 0.5, invalid)
    assert invalid[4].all() and not invalid[:4].all()  # both kinds are tested
    assert np.abs(fast - want)[~invalid].max() <= 1e-5
    order = np.sort(want, axis=0)
    clear = order[1] - order[0] > 1e-5
    assert np.array_equal(np.argmin(fast, 0)[clear], np.argmin(want, 0)[clear])


def test_no_query_pixel_gives_no_cost() -> None:
    grid = surfaces((64, 64))
    assert grid.disparity_range is not None
    lo, hi = grid.disparity_range
    level = SweepLevel(grid, "r1c1", [n for n in grid.names if n != "r1c1"], 1.0, (0, 64, 0, 64), (lo, hi))
    cands = [np.full((64, 64), np.float32(lo))]
    out = referee(level, cands, np.zeros((64, 64), bool), 3, 4, True)
    assert out.shape == (1, 0)


@pytest.mark.parametrize(
    "box,win", [((40, 41, 20, 60), 5), ((40, 43, 30, 33), 9), ((40, 42, 10, 50), 7), ((20, 60, 5, 8), 4)]
)
def test_windows_wider_than_the_crop_or_even_take_the_reference(box: tuple[int, int, int, int], win: int) -> None:
    """A window the crop cannot reflect once, or an even one (OpenCV's is off-centre): the reference's costs."""
    grid = surfaces((96, 128))
    assert grid.disparity_range is not None
    lo, hi = grid.disparity_range
    level = SweepLevel(grid, "r1c1", [n for n in grid.names if n != "r1c1"], 1.0, box, (lo, hi))
    shape = (box[1] - box[0], box[3] - box[2])
    cands = [np.full(shape, np.float32(0.5 * (lo + hi)))]
    where = np.ones(shape, bool)
    np.testing.assert_array_equal(
        referee(level, cands, where, win, 4, True), referee(level, cands, where, win, 4, False)
    )


def test_a_sample_however_far_outside_replicates_the_edge() -> None:
    """A window pixel whose disparity puts its sample 1e30 px away (an integer conversion that would overflow)
    samples the part's edge, as the reference's remap does: within the tolerance of the rest."""
    grid = surfaces((96, 128))
    assert grid.disparity_range is not None
    lo, hi = grid.disparity_range
    box = (10, 80, 10, 110)
    level = SweepLevel(grid, "r1c1", [n for n in grid.names if n != "r1c1"], 1.0, box, (lo, hi))
    shape = (box[1] - box[0], box[3] - box[2])
    where = np.zeros(shape, bool)
    where[30, 40] = where[31, 41] = True
    for far in (1e30, -1e30, 1e10):
        cand = np.full(shape, np.float32(0.5 * (lo + hi)))
        cand[29, 40] = far  # a neighbour in the windows of both query pixels
        fast = referee(level, [cand], where, 3, 4, True)
        want = referee(level, [cand], where, 3, 4, False)
        assert np.abs(fast - want).max() <= 1e-5, (far, fast, want)
