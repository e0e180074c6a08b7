"""The temporal stabiliser on small synthetic grids with exact disparity: the noise it measures from the frames,
what it calls a change, what it keeps, what it replaces, and that it never drags what moved."""

from __future__ import annotations

import copy
import itertools

import cv2
import numpy as np
import pytest

from rigctl.depth.estimate import DepthResult
from rigctl.depth.grid import Grid, grid_from_arrays
from rigctl.depth.temporal import Temporal, TemporalParams
from rigctl.depth.temporal_change import FrameChange, HalfPictures, NoiseHistory, frame_change, still_in_every_view
from rigctl.errors import ParameterError

H, W = 96, 128
D_BACK, D_FRONT = 3.0, 7.0


def texture(seed: int, h: int = H + 60, w: int = W + 60) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.asarray(cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), 1.5) * 0.6 + 0.2, np.float32)


def scene(square_x: int | None, noise: float, seed: int, gain: float = 1.0, only: str | None = None) -> Grid:
    """A 3x3 grid (spacing ratio 1) of a textured wall at D_BACK and a textured square at D_FRONT whose left
    edge is at ``square_x`` in r1c1 (None: no square), 8-bit with Gaussian noise of ``noise`` levels;
    ``only``: the square is drawn in that camera alone (a change one view sees)."""
    back, front = texture(1), texture(2)
    rng = np.random.default_rng(seed)
    gy, gx = np.mgrid[0:H, 0:W].astype(np.float32)
    images = {}
    for r in range(3):
        for c in range(3):
            name = f"r{r}c{c}"
            ox, oy = c - 1.0, r - 1.0
            # a point at r1c1's (x, y) with disparity d lies at (x - d ox, y - d oy) in this camera
            img = cv2.remap(back, gx + D_BACK * ox + 30, gy + D_BACK * oy + 30, cv2.INTER_LINEAR)
            if square_x is not None and (only is None or only == name):
                sx, sy = gx + D_FRONT * ox, gy + D_FRONT * oy
                inside = (sx >= square_x) & (sx < square_x + 40) & (sy >= 28) & (sy < 68)
                img = np.where(inside, cv2.remap(front, sx - square_x + 10, sy + 10, cv2.INTER_LINEAR), img)
            noisy = img * gain * 255 + rng.normal(0, noise, img.shape)
            images[name] = np.repeat(np.clip(np.rint(noisy), 0, 255).astype(np.uint8)[..., None], 3, axis=2)
    return grid_from_arrays(images, 1000.0, 0.1, 0.1)


def truth(square_x: int | None) -> np.ndarray:
    d = np.full((H, W), D_BACK, np.float32)
    if square_x is not None:
        d[28:68, square_x : square_x + 40] = D_FRONT
    return d


def result(d: np.ndarray) -> DepthResult:
    z = np.zeros(d.shape, bool)
    return DepthResult(d.astype(np.float32), np.ones(d.shape, np.float32), z, z.copy(), np.ones(d.shape, np.float32))


def run(grids: list[Grid], estimates: list[np.ndarray], params: TemporalParams | None = None) -> list[DepthResult]:
    temporal, out = Temporal(params), []
    for g, d in zip(grids, estimates, strict=True):
        res = temporal.stabilise(g, "r1c1", result(d.copy()), (0.0, 10.0))
        temporal.advance(g, {"r1c1": res})
        out.append(res)
    return out


@pytest.mark.parametrize("noise", [1.0, 3.0])
def test_the_noise_is_measured_from_the_frames_and_a_moved_square_is_seen_above_it(noise: float) -> None:
    history: dict[str, NoiseHistory] = {}
    a, b = scene(40, noise, 1), scene(40, noise, 2)
    still = frame_change(a, b, history, 5, 6.0)
    # the half-size picture averages four pixels: half the noise
    assert history["r1c1"].sigma() == pytest.approx(noise / 2, rel=0.25)
    assert max(still.share.values()) < 0.03, still.share  # a false alarm is a 6 px block: 0.3 % of this picture
    moved = frame_change(b, scene(46, noise, 3), history, 5, 6.0)
    assert moved.changed["r1c1"][30:66, 42:84].all()  # the square's old and new place
    # far from the square: at most a false alarm (a 6 px block, 1.3 % of this strip) or two
    assert moved.changed["r1c1"][:, :30].mean() < 0.03 and moved.changed["r1c1"][:, 100:].mean() < 0.03


def test_a_change_of_exposure_is_not_motion() -> None:
    change = frame_change(scene(40, 1.0, 1), scene(40, 1.0, 2, gain=1.08), {}, 5, 6.0)
    assert max(change.share.values()) < 0.03, change.share


def test_a_change_that_only_another_view_sees_makes_the_pixel_new() -> None:
    """The square appears in r1c2 alone: r1c1's pixels where r1c2 sees it (at x - D_BACK) are not still, even
    though r1c1's own colour did not change."""
    a, b = scene(None, 1.0, 1), scene(40, 1.0, 2, only="r1c2")
    change = frame_change(a, b, {}, 5, 6.0)
    assert change.changed["r1c1"].sum() == 0
    still = still_in_every_view(change, b, "r1c1", truth(None))
    seen = np.zeros((H, W), bool)
    seen[30:66, 38:74] = True  # r1c2 shows the square at [33, 73): r1c1's pixels x - 3 (the wall's disparity)
    assert not still[seen].any() and still[:, :30].mean() > 0.97


def test_a_still_scene_settles_and_an_outlier_of_one_frame_is_not_taken() -> None:
    rng = np.random.default_rng(0)
    grids = [scene(40, 1.0, s) for s in range(8)]
    estimates = [truth(40) + rng.normal(0, 0.15, (H, W)).astype(np.float32) for _ in grids]
    estimates[5][50:60, 90:100] += 4.0  # a mismatch in one frame only
    out = run(grids, estimates)
    raw = np.mean([np.abs(b - a).mean() for a, b in itertools.pairwise(estimates)])
    stab = np.mean([np.abs(b.disparity - a.disparity).mean() for a, b in itertools.pairwise(out)])
    assert stab < raw / 4, (stab, raw)
    assert np.abs(out[5].disparity[50:60, 90:100] - D_BACK).max() < 0.5  # the wall's depth stayed
    assert np.abs(out[-1].disparity - truth(40)).mean() < 0.5 * np.abs(estimates[-1] - truth(40)).mean()
    assert out[1].stats["temporal_blended_share"] > 0.9 and out[5].stats["temporal_kept_share"] > 0
    assert out[0].stats.get("temporal_blended_share") is None  # nothing before the first frame


def test_an_error_of_the_first_frame_is_replaced_when_the_views_say_so() -> None:
    grids = [scene(40, 1.0, s) for s in range(3)]
    first = truth(40)
    first[10:20, 90:110] += 3.0  # wrong in the first frame: the views disagree with it
    out = run(grids, [first, truth(40), truth(40)])
    assert np.abs(out[1].disparity[10:20, 90:110] - D_BACK).max() < 0.3
    assert out[1].stats["temporal_replaced_share"] > 0


def test_a_moving_square_is_not_dragged() -> None:
    """The square moves 6 px right: where it left and where it arrived the output is the new estimate."""
    grids = [scene(40, 1.0, 0), scene(40, 1.0, 1), scene(46, 1.0, 2)]
    out = run(grids, [truth(40), truth(40), truth(46)])
    moved = truth(40) != truth(46)
    assert np.array_equal(out[2].disparity[moved], truth(46)[moved])
    assert np.abs(out[2].disparity - truth(46)).max() < 1e-6
    assert out[2].stats["temporal_new_share"] > 0.12  # the square's old and new place: 40 x 46 px and a rim


def test_the_same_frames_give_the_same_bytes_and_reset_or_disabled_pass_through() -> None:
    rng = np.random.default_rng(1)
    grids = [scene(40, 1.0, s) for s in range(3)]
    estimates = [truth(40) + rng.normal(0, 0.2, (H, W)).astype(np.float32) for _ in grids]
    a, b = run(grids, estimates), run(grids, estimates)
    assert all(x.disparity.tobytes() == y.disparity.tobytes() for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[2].disparity, estimates[2])
    off = run(grids, estimates, TemporalParams(enabled=False))
    assert all(np.array_equal(o.disparity, e) for o, e in zip(off, estimates, strict=True))
    temporal = Temporal()
    temporal.advance(grids[0], {"r1c1": result(estimates[0])})
    temporal.reset()
    res = temporal.stabilise(grids[1], "r1c1", copy.copy(result(estimates[1])), (0.0, 10.0))
    assert np.array_equal(res.disparity, estimates[1])


def test_the_noise_is_measured_where_the_picture_is_flat_so_a_large_moving_subject_does_not_raise_it() -> None:
    """A textured card over 60 % of the picture moves 4 px in front of a flat screen: most pixels change, so the
    median of the change statistic is the card's motion, not the noise; the flat screen still shows the noise."""
    card = texture(5, 240, 320)

    def picture(x: int, seed: int) -> Grid:
        img = np.full((240, 320), 0.45, np.float32)
        img[24:216, 8:248] = card[24:216, x : x + 240]
        noisy = np.clip(np.rint(img * 255 + np.random.default_rng(seed).normal(0, 2.0, img.shape)), 0, 255)
        u8 = np.repeat(noisy.astype(np.uint8)[..., None], 3, axis=2)
        return grid_from_arrays({"r0c0": u8, "r0c1": u8.copy()}, 1000.0, 0.1, 0.1)

    history: dict[str, NoiseHistory] = {}
    change = frame_change(picture(10, 1), picture(14, 2), history, 5, 6.0)
    assert history["r0c0"].sigma() == pytest.approx(1.0, rel=0.3)  # 2 levels at full size, half at half size
    assert change.changed["r0c0"][28:212, 12:244].mean() > 0.95
    assert change.changed["r0c0"][:, 260:].mean() < 0.01


def test_a_running_mean_longer_than_a_byte_counts_is_refused() -> None:
    """The frames in each pixel's mean are counted in a byte a pixel (issue 24: a chunk's memory)."""
    assert TemporalParams(max_frames=255).max_frames == 255
    for bad in (0, 256, -1):
        with pytest.raises(ParameterError, match="max_frames must be 1 to 255"):
            TemporalParams(max_frames=bad)


def whole_crop_costs(grid: Grid, d_new: np.ndarray, d_prev: np.ndarray, where: np.ndarray) -> np.ndarray:
    """The deciding costs as the stabiliser computed them before issue 24's bands: one box around every pixel
    of ``where`` and every view's whole normalised frame."""
    import math

    from rigctl.depth.cost import SweepLevel

    p, ref = TemporalParams(), "r1c1"
    views = [n for n in grid.names if n != ref]
    ys, xs = np.nonzero(where)
    r = p.cost_window
    y0, y1, x0, x1 = max(0, ys.min() - r), min(H, ys.max() + r + 1), max(0, xs.min() - r), min(W, xs.max() + r + 1)
    level = SweepLevel(grid, ref, views, 1.0, (y0, y1, x0, x1))
    a, b = d_new[y0:y1, x0:x1], d_prev[y0:y1, x0:x1]
    a_f = np.where(np.isfinite(a), a, np.where(np.isfinite(b), b, 0.0)).astype(np.float32)
    b_f = np.where(np.isfinite(b), b, a_f).astype(np.float32)
    return level.costs_where([a_f, b_f], where[y0:y1, x0:x1], r, math.ceil(p.cost_keep * len(views)))


@pytest.mark.parametrize("band", [1, 7, 13, 128])
def test_the_deciding_costs_in_bands_are_the_whole_crops(band: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The costs that decide between the new and the previous depth are matched in bands of rows, each view
    only where the band's candidates reach (issue 24: a chunk's memory at 3840x2160), and are the same bits
    as over one crop with every view's whole frame: pixels at the frame's edges, estimates missing in either
    or both, candidates that reach out of the frame or that no view sees."""
    import rigctl.depth.temporal as temporal_module

    rng = np.random.default_rng(3)
    grid = scene(40, 2.0, 4)
    d_new = (truth(40) + rng.normal(0, 0.3, (H, W))).astype(np.float32)
    d_prev = (truth(None) + rng.normal(0, 0.3, (H, W))).astype(np.float32)
    d_new[rng.random((H, W)) < 0.1] = np.nan
    d_prev[rng.random((H, W)) < 0.1] = np.nan
    d_prev[50:60, 90:100] = 20.0  # a band whose reach is set by a few pixels
    d_prev[0:6, 0:10] = 40.0  # samples beyond the frame
    d_new[0:12, 100:] = d_prev[0:12, 100:] = 400.0  # a band whose every sample lies beyond every view's frame
    where = rng.random((H, W)) < 0.15
    where[0:3] = False  # rows 0 to 2: that band alone
    where[0:3, 110:120] = where[3, :5] = where[-1, -5:] = where[55, 95] = True
    reference = whole_crop_costs(grid, d_new, d_prev, where)
    monkeypatch.setattr(temporal_module, "COST_BAND_ROWS", band)
    c_new, c_prev = Temporal()._costs(grid, "r1c1", d_new, d_prev, where)
    assert np.array_equal(c_new, reference[0]) and np.array_equal(c_prev, reference[1])
    assert (c_new != c_prev).mean() > 0.5
    empty = Temporal()._costs(grid, "r1c1", d_new, d_prev, np.zeros((H, W), bool))
    assert empty[0].size == empty[1].size == 0


def whole_frame_still(change: FrameChange, grid: Grid, ref: str, disparity: np.ndarray) -> np.ndarray:
    """``still_in_every_view`` as it was before issue 24's box: coordinate grids and maps of the whole frame."""
    h, w = disparity.shape
    have = np.isfinite(disparity)
    still = have & (change.changed[ref] == 0)
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
    d = np.where(have, disparity, 0.0).astype(np.float32)
    ox, oy = grid.offsets[ref]
    for name, moved in change.changed.items():
        rx, ry = grid.offsets[name][0] - ox, grid.offsets[name][1] - oy
        if name == ref or (abs(rx) < 1e-9 and abs(ry) < 1e-9):
            continue
        mx, my = gx - d * np.float32(rx), gy - d * np.float32(ry)
        seen = cv2.remap(moved, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        still &= seen == 0
    return still


@pytest.mark.parametrize("where", ["middle", "corner", "edges", "none", "one pixel"])
def test_the_still_test_on_the_box_of_the_estimates_is_the_whole_frames(where: str) -> None:
    """Issue 24, a chunk's memory: the still test maps only the box of the pixels that can be still, each
    pixel's map the same number as the whole frame's (subjects at the frame's edges, NaN, +inf, fractions)."""
    rng = np.random.default_rng(7)
    grid = scene(50, 1.0, 1)
    changed = {n: (rng.random((H, W)) < 0.02).astype(np.uint8) for n in grid.names}
    changed["r0c2"][:, :20] = 1  # a view whose edge changed: points near x=0 in r1c1 that it sees there
    change = FrameChange(changed, {n: 1.0 for n in grid.names}, {n: 0.0 for n in grid.names})
    d = np.full((H, W), np.nan, np.float32)
    if where == "middle":
        d[30:60, 40:90] = rng.uniform(-2.0, 9.5, (30, 50)).astype(np.float32)
    elif where == "corner":
        d[H - 20 :, W - 25 :] = rng.uniform(0.0, 30.0, (20, 25)).astype(np.float32)
    elif where == "edges":
        d[:, :7] = 3.25
        d[0, :] = rng.uniform(-40.0, 40.0, W).astype(np.float32)
        d[H - 1, W - 1] = np.inf
    elif where == "one pixel":
        d[H // 2, 3] = 2.5
    got = still_in_every_view(change, grid, "r1c1", d)
    assert got.shape == (H, W) and got.dtype == bool
    np.testing.assert_array_equal(got, whole_frame_still(change, grid, "r1c1", d))
    if where in ("middle", "corner"):
        assert 0 < got.sum() < np.isfinite(d).sum()  # some pixels still, some seen moving by a view


def test_the_change_test_lets_go_of_both_frame_sets_pictures() -> None:
    """Issue 24, a chunk's memory: the previous frame set's half-size pictures are let go of as the change test
    reads them, and the test keeps none of this frame set's (``advance`` makes them again once it is done);
    the stabilised results are those of a stabiliser that kept them (the same values made again)."""
    a, b, c = scene(50, 1.0, 1), scene(50, 1.0, 2), scene(54, 1.0, 3)
    temporal = Temporal()
    out = []
    for grid in (a, b, c):
        results = {
            n: temporal.stabilise(grid, n, result(truth(50) + 0.01 * len(out)), (0.0, 10.0)) for n in ("r1c1", "r0c0")
        }
        if temporal.previous is not None:
            assert temporal.previous.pictures.pictures == {}  # read and let go of
            assert temporal._change is not None and not hasattr(temporal._change[1], "pictures")
        out.append({n: r.disparity.copy() for n, r in results.items()})
        temporal.advance(grid, results)
        assert temporal.previous is not None and set(temporal.previous.pictures.pictures) == set(grid.names)
    assert out[1]["r1c1"][40, 60] != out[0]["r1c1"][40, 60]  # the second frame set was stabilised
    # against the change test fed the half-size pictures straight from the grids
    history: dict[str, NoiseHistory] = {}
    first = frame_change(a, b, history, 5, 6.0)
    kept: dict[str, NoiseHistory] = {}
    again = frame_change(HalfPictures.of(a).made(), b, kept, 5, 6.0)
    for n in a.names:
        np.testing.assert_array_equal(first.changed[n], again.changed[n])
    assert history["r1c1"].levels == kept["r1c1"].levels
