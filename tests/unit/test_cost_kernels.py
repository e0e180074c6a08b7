"""The cost volume's compiled matching cost (``rigctl/depth/cost_kernels.py``) against the OpenCV and numpy
reference it replaces (``combine(MatchViews.view_costs(d, win), keep)``), on a textured scene with slanted
and curved surfaces, an off-centre crop, both scales the sweep uses, constant disparities (integer and
fractional) and per-pixel maps that reach outside the views.

Tolerance: the same pixels are INVALID (no view sees the point); elsewhere, at a per-pixel map, within 1e-5
of the reference (costs run 0..1.5: float32 rounding of the bilinear weights and the box sums); at a
constant disparity within 1e-3, because OpenCV's ``warpAffine`` places the samples in double precision where
the kernel, like ``remap``, uses float32 positions (a 1e-5 px difference of position times the steepest
intensity step)."""

from __future__ import annotations

import numpy as np
import pytest

import rigctl.depth.costvolume as cvm
from rigctl.depth.cost import INVALID_COST
from rigctl.depth.scenes import surfaces


def both(views: cvm.MatchViews, d: float | np.ndarray, win: int, keep: int) -> tuple[np.ndarray, np.ndarray]:
    cvm.COMPILED = True
    try:
        fast = views.costs(d, win, keep)
    finally:
        cvm.COMPILED = True
    cvm.COMPILED = False
    try:
        ref = views.costs(d, win, keep)
    finally:
        cvm.COMPILED = True
    return fast, ref


def surface_views(
    size: tuple[int, int], box: tuple[int, int, int, int], scale: float
) -> tuple[cvm.MatchViews, tuple[float, float]]:
    """The centre camera's views of the surfaces scene on ``box``, and the scene's disparity range."""
    grid = surfaces(size)
    ref = "r1c1"
    ox, oy = grid.offsets[ref]
    rel = {n: (grid.offsets[n][0] - ox, grid.offsets[n][1] - oy) for n in grid.images if n != ref}
    assert grid.disparity_range is not None
    lo, hi = grid.disparity_range
    return cvm.MatchViews(dict(grid.images), ref, rel, box, scale, 0.5 * (lo + hi)), (lo, hi)


@pytest.mark.parametrize("scale", [1.0, 0.5])
@pytest.mark.parametrize("win,keep", [(3, 4), (1, 4), (3, 8), (5, 2)])
def test_the_compiled_cost_matches_the_reference(scale: float, win: int, keep: int) -> None:
    views, (lo, hi) = surface_views((96, 128), (10, 90, 6, 120), scale)
    rng = np.random.default_rng(1)
    maps = [
        (rng.uniform(lo, hi, views.shape) * scale).astype(np.float32),
        np.full(views.shape, 30.0, np.float32) + rng.uniform(-0.5, 0.5, views.shape).astype(np.float32),  # outside
    ]
    for d, tol in [(float(round(lo * scale)), 1e-3), (hi * scale + 0.37, 1e-3), *((m, 1e-5) for m in maps)]:
        fast, want = both(views, d, win, keep)
        invalid = want >= INVALID_COST * 0.5
        assert np.array_equal(fast >= INVALID_COST * 0.5, invalid)
        assert np.all(fast[invalid] == want[invalid])
        if (~invalid).any():
            assert np.abs(fast - want)[~invalid].max() <= tol


@pytest.mark.parametrize("limit", [False, True])
def test_the_compiled_better_half_matches_the_numpy_reference_bit_for_bit(limit: bool) -> None:
    """``edge.sensor_fixed``'s mean over the better half of the views: compiled (insertion sort, running
    float32 sum) against the reference (np.sort, np.cumsum), identical bits; unseen views (inf), pixels no view
    sees, ties, and a view budget ``seen_by`` smaller and larger than the views seen."""
    from rigctl.depth.cost_kernels import better_half_mean
    from rigctl.depth.edge import _better_half_reference

    rng = np.random.default_rng(3)
    h, w, nv = 37, 53, 8
    stack = rng.random((h, w, nv), dtype=np.float32) * np.float32(0.2)
    stack[rng.random((h, w, nv)) < 0.3] = np.inf  # views that do not see the point
    stack[:3] = np.inf  # rows no view sees
    stack[5, :, :4] = np.float32(0.05)  # ties
    seen_by = rng.integers(0, nv + 2, (h, w)).astype(np.float32) if limit else None
    mean, count = better_half_mean(stack, seen_by)
    ref_mean, ref_count = _better_half_reference(stack, seen_by)
    assert np.array_equal(count, ref_count)
    assert np.array_equal(mean, ref_mean)  # inf where none is seen, in both
    assert np.isinf(mean[:3]).all() and (count[:3] == 0).all()
    views = count if seen_by is None else np.minimum(count, seen_by)
    assert np.isfinite(mean[views > 0]).all() and np.isinf(mean[views == 0]).all()


@pytest.mark.parametrize("keep", [4, 8, 2])
def test_the_compiled_refinement_matches_the_reference(keep: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """``refine.refine``'s normal equations by ``refine_kernels.refine_sums`` against the OpenCV and numpy
    path, on the textured scene with a noisy start that reaches outside the views at the crop's edge.

    Tolerance: each step's aggregated sums within 1e-5 of their largest value (the 5x5 means are summed in
    double directly, OpenCV's box filter by running sums); after three steps the refined maps within 0.01 px
    everywhere and 1e-3 px on 99.9 % of the pixels (where two views' local fits tie to rounding, either may
    be the one kept)."""
    import rigctl.depth.refine as rf
    from rigctl.depth.costvolume import Aggregator

    grid = surfaces((96, 128))
    ref = "r1c1"
    ox, oy = grid.offsets[ref]
    rel = {n: (grid.offsets[n][0] - ox, grid.offsets[n][1] - oy) for n in grid.images if n != ref}
    assert grid.disparity_range is not None and grid.truth is not None
    lo, hi = grid.disparity_range
    views = cvm.MatchViews(dict(grid.images), ref, rel, (4, 92, 2, 126), 1.0, 0.5 * (lo + hi))
    truth = grid.truth[ref][4:92, 2:126]
    rng = np.random.default_rng(2)
    start = (np.where(np.isfinite(truth), truth, lo) + rng.normal(0, 0.2, truth.shape)).astype(np.float32)
    agg = Aggregator(views.guide, 4, 1e-4)
    monkeypatch.setattr(rf, "COMPILED", False)
    a_ref, b_ref = rf._normal_equations(views, start, keep, agg)
    out_ref, _ = rf.refine(views, start, keep, 4, 1e-4, 3, reach=0.25)
    monkeypatch.setattr(rf, "COMPILED", True)
    a_raw, b_raw = rf.refine_sums(views.levels, views.ref, views.rel_array, start, (4, 2), keep, INVALID_COST, rf.TAU_I)
    a, b = agg.smooth(a_raw), agg.smooth(b_raw)
    assert np.abs(a - a_ref).max() <= 1e-5 * np.abs(a_ref).max()
    assert np.abs(b - b_ref).max() <= 1e-5 * np.abs(b_ref).max()
    out, _ = rf.refine(views, start, keep, 4, 1e-4, 3, reach=0.25)
    diff = np.abs(out - out_ref)
    assert np.isfinite(out).all() and diff.max() <= 0.01 and (diff > 1e-3).mean() <= 1e-3
    assert np.abs(out - start).max() > 0.01  # the steps moved the map: not a comparison of two no-ops


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_views_cut_to_the_range_give_the_whole_views_costs_and_steps_bit_for_bit(scale: float) -> None:
    """MatchViews with ``reach`` keeps of each view only the part the range reaches from the crop (issue 24:
    memory that follows the crop, not the frame); the compiled cost, the reference path and the refinement's
    sums must be the same bits as with the whole views, at disparities across the range and a little beyond.
    The OpenCV reference path too, but at a constant disparity within 1e-5: ``warpAffine`` rounds the
    translation's fraction together with its integer part, which the part's origin changes."""
    import rigctl.depth.refine as rf

    grid = surfaces((96, 160))
    ref = "r1c1"
    ox, oy = grid.offsets[ref]
    rel = {n: (grid.offsets[n][0] - ox, grid.offsets[n][1] - oy) for n in grid.images if n != ref}
    assert grid.disparity_range is not None
    lo, hi = grid.disparity_range
    box = (30, 70, 50, 110)  # a crop away from every edge: the parts are smaller than the frame
    whole = cvm.MatchViews(dict(grid.images), ref, rel, box, scale, 0.5 * (lo + hi))
    cut = cvm.MatchViews(dict(grid.images), ref, rel, box, scale, 0.5 * (lo + hi), (lo - 2.0, hi + 2.0))
    assert cut.levels.shape[1] * cut.levels.shape[2] < 0.8 * whole.levels.shape[1] * whole.levels.shape[2]
    rng = np.random.default_rng(4)
    maps = [(rng.uniform(lo - 1.5, hi + 1.5, whole.shape) * scale).astype(np.float32) for _ in range(2)]
    for d in [float(round(lo * scale)), hi * scale + 0.37, (lo - 1.0) * scale, *maps]:
        assert np.array_equal(cut.costs(d, 3, 4), whole.costs(d, 3, 4))
        cvm.COMPILED = False
        try:
            a, b = cut.costs(d, 3, 4), whole.costs(d, 3, 4)
        finally:
            cvm.COMPILED = True
        assert np.array_equal(a, b) if isinstance(d, np.ndarray) else np.abs(a - b).max() <= 1e-5
    y0, _, x0, _ = whole.box
    for m in maps:
        want = rf.refine_sums(whole.levels, whole.ref, whole.rel_array, m, (y0, x0), 4, INVALID_COST, rf.TAU_I)
        got = rf.refine_sums(
            cut.levels, cut.ref, cut.rel_array, m, (y0, x0), 4, INVALID_COST, rf.TAU_I, cut.org, (cut.h, cut.w)
        )
        assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))
    for name in rel:
        assert all(
            np.array_equal(a, b) for a, b in zip(cut.warp(name, maps[0]), whole.warp(name, maps[0]), strict=True)
        )


def test_row_blocks_give_the_one_pass_bits(monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled cost and the refinement's sums run in blocks of ``ROWS`` rows (issue 24: the per-view
    arrays are a block's, not the crop's): blocks of 5 rows, with the cost window's and the 5x5's rows around
    each, give the bits of one block over the whole crop, at a constant disparity and at a map."""
    import rigctl.depth.cost_kernels as ck
    import rigctl.depth.refine as rf

    views, (lo, hi) = surface_views((96, 128), (3, 91, 2, 126), 1.0)
    d = np.random.default_rng(5).uniform(lo, hi, views.shape).astype(np.float32)

    def run() -> list[np.ndarray]:
        y0, _, x0, _ = views.box
        sums = rf.refine_sums(views.levels, views.ref, views.rel_array, d, (y0, x0), 4, INVALID_COST, rf.TAU_I)
        return [views.costs(d, 3, 4), views.costs(d, 5, 2), views.costs(float(round(lo)), 3, 4), *sums]

    monkeypatch.setattr(ck, "ROWS", 10_000)
    whole = run()
    monkeypatch.setattr(ck, "ROWS", 5)
    assert all(np.array_equal(a, b) for a, b in zip(run(), whole, strict=True))


def test_sweep_level_cut_to_the_reach_gives_the_whole_views_costs() -> None:
    """The pairs engine's SweepLevel keeps only the part of each view that its candidates reach from the box
    (issue 24): the costs at the candidates' pixels and over the box are the same bits as with whole views."""
    from rigctl.depth.cost import SweepLevel

    grid = surfaces((96, 160))
    ref = "r1c1"
    views = [n for n in grid.names if n != ref]
    assert grid.disparity_range is not None
    lo, hi = grid.disparity_range
    box = (30, 70, 50, 110)
    rng = np.random.default_rng(6)
    cands = [rng.uniform(lo - 1, hi + 1, (40, 60)).astype(np.float32) for _ in range(3)]
    reach = (min(float(c.min()) for c in cands), max(float(c.max()) for c in cands))
    whole = SweepLevel(grid, ref, views, 1.0, box)
    cut = SweepLevel(grid, ref, views, 1.0, box, reach)
    assert sum(v.size for v in cut.norm.values()) < 0.8 * sum(v.size for v in whole.norm.values())
    where = rng.random((40, 60)) < 0.3
    assert np.array_equal(cut.costs_where(cands, where, 3, 4), whole.costs_where(cands, where, 3, 4))
    assert np.array_equal(cut.cost_map(cands[0], 3), whole.cost_map(cands[0], 3))


@pytest.mark.parametrize("eight_bit", [False, True])
def test_sweep_level_reads_only_the_greys_rows_it_needs_and_gets_the_whole_greys_values(
    eight_bit: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """At full scale a SweepLevel reads each camera's grey only over its part's rows and the normalisation's
    window around them (issue 24: the greys are not all kept at 4K); the reference's and every view's
    normalised part are the bits the whole grey gives, boxes at the frame's edges and inside it."""
    import rigctl.depth.grid as grid_module
    from rigctl.depth.cost import SweepLevel, normalise
    from rigctl.depth.grid import Grid, grey
    from rigctl.pixfmt import to_u8

    base = surfaces((96, 160))
    images = {n: to_u8(base.images[n]) if eight_bit else base.images[n] for n in base.names}
    grid = Grid(list(base.names), images, dict(base.offsets), base.focal_px, base.spacing, base.doffs)
    monkeypatch.setattr(grid_module, "GREY_KEEP_BYTES", 0)  # nothing kept: every read makes its rows
    ref = "r1c1"
    views = [n for n in grid.names if n != ref]
    whole = {n: normalise(grey(grid.images[n])) for n in grid.names}
    for box, reach in (((30, 70, 50, 110), (1.0, 4.0)), ((0, 96, 0, 160), None), ((0, 9, 150, 160), (-3.0, 2.0))):
        level = SweepLevel(grid, ref, views, 1.0, box, reach)
        y0, y1, x0, x1 = box
        assert np.array_equal(level.ref, whole[ref][0][y0:y1, x0:x1])
        assert np.array_equal(level.texture, whole[ref][1][y0:y1, x0:x1])
        assert np.array_equal(level.bright, grey(grid.images[ref])[y0:y1, x0:x1])
        for n in views:
            (a, b), (h, w) = level.org[n], level.norm[n].shape
            assert np.array_equal(level.norm[n], whole[n][0][a : a + h, b : b + w]), (box, n)
    assert grid.frames.made_bytes() == (grid.frames._last[1].nbytes if grid.frames._last else 0)


def test_the_compiled_visible_count_matches_the_reference() -> None:
    """Views that see each pixel's point (inside the frame, not behind a nearer pixel of the reference), on
    a crop whose disparity has steps up and down, parts keyed out (no occluders there) and points beyond
    the frame."""
    grid = surfaces((96, 128))
    ref = "r1c1"
    ox, oy = grid.offsets[ref]
    rel = {n: (grid.offsets[n][0] - ox, grid.offsets[n][1] - oy) for n in grid.images if n != ref}
    views = cvm.MatchViews(dict(grid.images), ref, rel, (10, 90, 6, 120))
    rng = np.random.default_rng(3)
    d = np.full(views.shape, 2.0, np.float32) + rng.uniform(-0.3, 0.3, views.shape).astype(np.float32)
    d[20:50, 30:70] += 9.0
    d[55:70, 80:100] -= 1.5
    d[:, :4] = 40.0  # beyond some views' frames
    front = np.ones(views.shape, bool)
    front[60:80, 10:40] = False
    cvm.COMPILED = False
    try:
        want = views.visible_count(d, front)
    finally:
        cvm.COMPILED = True
    got = views.visible_count(d, front)
    assert np.array_equal(got, want)
    assert (want < len(rel)).any() and (want == len(rel)).any()
    # counted only where asked (the report's pixels), the same counts there and none elsewhere
    assert np.array_equal(views.visible_count(d, front, where=front), np.where(front, want, 0))
    # the splat in bands of rows, each written only from the rows that can land there: the same counts for
    # any number of bands (one, a band boundary inside the steps, more bands than the views' rows)
    from rigctl.depth.visible_kernels import visible_views

    y0, _, x0, _ = views.box
    for bands in (1, 2, 7, 1000):
        got = visible_views(d, front, views.rel_array, (y0, x0), (views.h, views.w), cvm.OCCLUDER_PX, bands=bands)
        assert np.array_equal(got, want), bands


@pytest.mark.parametrize("win", [1, 3, 5])
def test_costs_on_the_active_pixels_alone_are_the_same_bits(win: int) -> None:
    """Issue 24: with ``active`` (the keyed subject grown by its context), each block of rows is computed on
    the columns its active pixels' windows span. There the costs are the whole crop's, bit for bit, at a
    constant disparity and at a map (samples outside the views included), and so are the refinement's sums;
    beside them INVALID (the sums 0); and fewer pixels are computed (a blob in one corner and a strip along
    the bottom, as a subject and a floor)."""
    from rigctl.depth.cost_kernels import ROWS, computed_pixels
    from rigctl.depth.refine_kernels import refine_sums

    views, (lo, hi) = surface_views((300, 200), (4, 296, 2, 198), 1.0)
    h, w = views.shape
    active = np.zeros((h, w), bool)
    active[20:150, 10:70] = True  # rows across a block boundary (ROWS)
    active[h - 12 :, :] = True
    assert ROWS < 150
    rng = np.random.default_rng(3)
    maps = [rng.uniform(lo, 3 * w, views.shape).astype(np.float32), np.full(views.shape, hi + 0.3, np.float32)]
    seen = []
    for d in [float(lo), hi + 0.37, *maps]:
        views.active = None
        whole = views.costs(d, win, 4)
        views.active = active
        part = views.costs(d, win, 4)
        assert np.array_equal(part[active], whole[active])
        seen.append(whole[active] < INVALID_COST * 0.5)
        assert (part[~active] == INVALID_COST).mean() > 0.5
    assert all(s.any() for s in seen) and not all(s.all() for s in seen)  # matches, and samples outside
    # the refinement's sums likewise (0 beside the active columns: no step there)
    y0, _, x0, _ = views.box
    args = (views.levels, views.ref, views.rel_array, maps[1] - 0.6, (y0, x0), 4, INVALID_COST, cvm.TAU_I)
    whole_sums = refine_sums(*args, views.org, (views.h, views.w))
    part_sums = refine_sums(*args, views.org, (views.h, views.w), active)
    for got, want in zip(part_sums, whole_sums, strict=True):
        assert np.array_equal(got[active], want[active]) and (want[active] != 0).mean() > 0.5
        assert (got[~active] == 0).mean() > 0.5
    assert computed_pixels(active, (h, w), win) < 0.6 * h * w
    assert computed_pixels(None, (h, w), win) == h * w
