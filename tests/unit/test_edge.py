"""Where the subject ends (``rigctl.depth.edge``): the coverage of edge pixels of a 4:2:2 picture, and
patterns fixed to the sensor, which match at zero disparity outside the range, getting no depth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from rigctl.depth.edge import DEPTH_COVERAGE, coverage
from rigctl.depth.estimate import estimate
from rigctl.depth.grid import grid_from_arrays
from rigctl.depth.presets import PRESETS
from rigctl.keying import Keyer

SCREEN = np.array([0.14, 0.54, 0.21], np.float32)


def textured(h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), 3.0)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    skin = np.array([0.25, 0.12, 0.08], np.float32) + tex[..., None] * np.array([0.55, 0.45, 0.35], np.float32)
    return np.asarray(skin, np.float32)


def four_two_two(rgb: np.ndarray) -> np.ndarray:
    """The picture as a 4:2:2 camera delivers it: BT.709 luma per pixel, chroma shared by pixel pairs."""
    m = np.array([[0.2126, 0.7152, 0.0722], [-0.1146, -0.3854, 0.5], [0.5, -0.4542, -0.0458]], np.float32)
    ycc = rgb @ m.T
    h, w = rgb.shape[:2]
    pairs = ycc[..., 1:].reshape(h, w // 2, 2, 2).mean(axis=2)
    ycc[..., 1:] = np.repeat(pairs, 2, axis=1)
    return np.asarray(np.clip(ycc @ np.linalg.inv(m).T, 0, 1), np.float32)


def subject_on_screen(h: int = 96, w: int = 128, ss: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """A textured subject (a disc and a slanted arm) on a green screen, rendered at ss x ss samples a pixel
    and delivered as 4:2:2; and its coverage (the share of each pixel's samples on the subject)."""
    yy, xx = (np.mgrid[0 : h * ss, 0 : w * ss] + 0.5) / ss
    inside = ((yy - 40.3) ** 2 + (xx - 60.7) ** 2 < 26.2**2) | ((np.abs((xx - 95) - 0.3 * (yy - 50)) < 4.6) & (yy > 30))
    fine = np.where(inside[..., None], cv2.resize(textured(h, w, 1), (w * ss, h * ss)), SCREEN)
    rgb = fine.reshape(h, ss, w, ss, 3).mean(axis=(1, 3)).astype(np.float32)
    cover = inside.reshape(h, ss, w, ss).mean(axis=(1, 3)).astype(np.float32)
    return four_two_two(rgb), cover


def test_coverage_decides_the_edge_pixels_where_the_soft_matte_spills_past_the_silhouette() -> None:
    """A sharp picture (one sample a pixel, as the simulator renders): the soft matte comes from the chroma
    the pixel pairs share, and the luma tells which pixel of the pair is the subject's."""
    rgb, cover = subject_on_screen()
    matte = Keyer().matte(rgb)
    truth = cover >= 0.5
    soft = (matte > 0) & (matte < 1)
    old = matte > 0  # what depth used before: every pixel the soft matte does not call pure screen
    new = coverage(rgb, matte) >= DEPTH_COVERAGE
    wrong_old, wrong_new = int((old != truth).sum()), int((new != truth).sum())
    false_old, false_new = int((old & ~truth).sum()), int((new & ~truth).sum())
    print(f"soft pixels {soft.sum()}: wrong {wrong_old} -> {wrong_new}, false foreground {false_old} -> {false_new}")
    assert soft.sum() > 100  # the test has an edge to decide
    assert wrong_new <= 0.5 * wrong_old, (wrong_old, wrong_new)
    assert false_new <= 0.25 * false_old, (false_old, false_new)
    assert np.array_equal(new[~soft], matte[~soft] > 0)  # pure subject and pure screen stay as the matte says


def test_coverage_of_an_antialiased_picture_is_no_worse_than_the_soft_matte() -> None:
    """Anti-aliased (8 x 8 samples a pixel): the matte is hard on most partly covered pixels (their pair's
    chroma looks pure), which the coverage leaves as they are; where it is soft, it is no worse."""
    rgb, cover = subject_on_screen(ss=8)
    matte = Keyer().matte(rgb)
    truth, edge = cover >= 0.5, (cover > 0) & (cover < 1)
    wrong_old = int(((matte > 0) != truth)[edge].sum())
    wrong_new = int(((coverage(rgb, matte) >= DEPTH_COVERAGE) != truth)[edge].sum())
    assert wrong_new <= wrong_old, (wrong_old, wrong_new)


def test_coverage_of_a_picture_without_soft_pixels_is_the_matte() -> None:
    matte = np.zeros((20, 30), np.float32)
    matte[5:15, 10:20] = 1.0
    rgb = np.where(matte[..., None] > 0, np.float32(0.5), SCREEN).astype(np.float32)
    assert np.array_equal(coverage(rgb, matte), matte)


@pytest.mark.parametrize("ss", [1, 8])
def test_the_compiled_coverage_is_the_reference_within_float32_rounding(ss: int) -> None:
    """Issue 24: the coverage made at the soft pixels by a compiled kernel, from each one's window, against the
    box filters over the frame (``coverage_reference``): the matte itself wherever it is not soft, the same
    mix within float32 rounding on the soft edge (the box filters' running sums round in float32), and so
    the same pixels with depth; at the frame's edges too (the subject cut by them, windows replicated)."""
    from rigctl.depth import edge

    rgb, _ = subject_on_screen(ss=ss)
    rng = np.random.default_rng(ss)
    cut = np.ascontiguousarray(rgb[20:, 40:])  # the disc and the arm reach the frame's top and left edges
    for picture in (rgb, cut):
        matte = Keyer().matte(picture)
        noisy = np.clip(matte + rng.normal(0, 0.2, matte.shape).astype(np.float32) * (matte > 0), 0, 1)
        for m in (matte, noisy.astype(np.float32)):
            soft = (m > 0) & (m < 1)
            got, want = edge.coverage(picture, m), edge.coverage_reference(picture, m)
            assert soft.sum() > 50 and got.dtype == np.float32
            assert np.array_equal(got[~soft], m[~soft])
            assert np.abs(got - want).max() <= 2e-6
            near = np.abs(want - DEPTH_COVERAGE) < 1e-5
            assert np.array_equal((got >= DEPTH_COVERAGE)[~near], (want >= DEPTH_COVERAGE)[~near])
            assert not np.array_equal(got[soft], m[soft])  # the mix, not the matte, on the edge


def plane_with_overlay(d: float, h: int = 120, w: int = 160) -> dict[str, np.ndarray]:
    """A textured plane at disparity ``d`` in a 3x3 grid, with a block pattern burnt into the same corner of
    every camera's picture (fixed to the sensor, as the simulator's frame id)."""
    rng = np.random.default_rng(4)
    noise = cv2.GaussianBlur(rng.random((h + 40, w + 400)).astype(np.float32), (0, 0), 1.2)
    blocks = np.repeat(np.repeat(rng.random((2, 16)) > 0.5, 3, axis=0), 3, axis=1).astype(np.float32)
    images = {}
    for r in range(3):
        for c in range(3):
            M = np.array([[1, 0, 200 + d * (c - 1)], [0, 1, 20 + d * (r - 1) * 0.65]], np.float32)
            img = cv2.warpAffine(noise, M, (w, h), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
            img[:6, :48] = 0.06 + 0.86 * blocks
            images[f"r{r}c{c}"] = np.repeat(np.clip(img, 0, 1)[..., None], 3, axis=2)
    return images


@pytest.mark.parametrize("preset", ["best", "pairs"])
def test_a_pattern_fixed_to_the_sensor_gets_no_depth_when_zero_is_outside_the_range(preset: str) -> None:
    images = plane_with_overlay(10.0)
    g = grid_from_arrays(images, 1000.0, 0.12, 0.12 * 0.65)
    r = estimate(g, "r1c1", (5.0, 20.0), PRESETS[preset], keyer=None)
    # the pattern's pixels lose their depth; those on its edge with the scene (their 3x3 window reaches
    # into the scene, which does not agree unshifted) may keep the scene's
    assert not np.isfinite(r.disparity[:5, :47]).any(), int(np.isfinite(r.disparity[:5, :47]).sum())
    assert r.stats["sensor_fixed_pixels"] >= 5 * 47
    inner = r.disparity[12:-12, 12:-12]
    assert np.isfinite(inner).mean() > 0.995  # the scene keeps its depth
    # with zero inside the range the pattern is a legitimate match (a background at infinity): kept
    wide = estimate(g, "r1c1", (-2.0, 20.0), PRESETS[preset], keyer=None)
    assert np.isfinite(wide.disparity[:6, :48]).mean() > 0.9
    assert wide.stats["sensor_fixed_pixels"] == 0


def _scene_disparities(names: list[str], offsets: dict[str, tuple[float, float]]) -> dict[str, np.ndarray]:
    """True disparities of a scene seen by a 3x3 lattice: a background surface (the torso) at 4 px with a
    square hand at 12 px in front of it, both on a screen (+inf), drawn in every camera at its own offset."""
    h, w = 80, 120
    out = {}
    for n in names:
        ox, oy = offsets[n]
        d = np.full((h, w), np.inf, np.float32)
        # a camera to the right sees a point d x dx further left: x_n = x_ref - d dx
        d[20 - round(4 * oy) : 65 - round(4 * oy), 30 - round(4 * ox) : 95 - round(4 * ox)] = 4.0
        d[35 - round(12 * oy) : 50 - round(12 * oy), 50 - round(12 * ox) : 70 - round(12 * ox)] = 12.0
        out[n] = d
    return out


def test_depth_in_front_of_what_the_other_views_see_takes_what_they_see() -> None:
    """Foreground fattened over the torso and over the screen in one camera (as a window matcher spreads an
    occluding edge) is put back: the torso's disparity where the others see torso, none where they see screen;
    everything else, occluded points included, is left alone."""
    from rigctl.depth.edge import occlusion_order, ordered

    names = [f"r{r}c{c}" for r in range(3) for c in range(3)]
    grid = grid_from_arrays({n: np.zeros((80, 120, 3), np.float32) for n in names}, 1000.0, 0.12, 0.078)
    truth = _scene_disparities(names, grid.offsets)
    fat = {n: d.copy() for n, d in truth.items()}
    ref = fat["r1c1"]
    hand = ref == 12.0
    grown = cv2.dilate(hand.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    ref[grown] = 12.0  # two pixels of hand over the torso around it
    halo = cv2.dilate(np.isfinite(truth["r1c1"]).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    ref[halo & ~np.isfinite(truth["r1c1"])] = 4.0  # a one-pixel halo of torso over the screen
    out = occlusion_order(grid, fat)
    flagged = out["r1c1"][0]
    fixed = ordered(fat["r1c1"], *out["r1c1"])
    wrong = (grown & ~hand) | (halo & ~np.isfinite(truth["r1c1"]))
    assert flagged[wrong].mean() > 0.95 and not flagged[~wrong].any()
    assert np.array_equal(np.isfinite(fixed), np.isfinite(truth["r1c1"]))
    assert np.abs(fixed[grown & ~hand] - 4.0).max() == 0.0
    for n in names:  # cameras whose depth is right are untouched, occluded torso beside the hand included
        if n != "r1c1":
            assert not out[n][0].any() and ordered(fat[n], *out[n]) is fat[n]


def test_the_sensor_tests_only_where_the_views_may_agree_unshifted_match_the_whole_box() -> None:
    """Issue 24: ``sensor_fixed`` tests only the pixels whose best view agrees unshifted within the margin
    (the mean of a better half is at least its best view's), sampling the views there alone. Against the
    reference over the whole box: the same four disagreements at those pixels (within float32 rounding: the
    window's mean sums in another order), the same count of views, no pixel left out that the reference
    would find agreeing unshifted, and the same pixels marked, with the pattern and the frame's edges (where
    views fall outside) in the box."""
    from rigctl.depth import edge

    images = plane_with_overlay(10.0)
    g = grid_from_arrays(images, 1000.0, 0.12, 0.12 * 0.65)
    rng = np.random.default_rng(7)
    d = np.full(g.shape, 10.0, np.float32) + rng.normal(0, 0.4, g.shape).astype(np.float32)
    d[40:60, 50:90] = np.inf  # a hole: the box keeps it, the tests leave it out
    views = [n for n in g.names if n != "r1c1"]
    h, w = g.shape
    box = (0, h, 0, w)
    dz = np.where(np.isfinite(d), d, 0.0).astype(np.float32)
    ref_y = np.asarray(g.images["r1c1"] @ edge.LUMA, np.float32)
    at, count, unshifted, nearby = edge._tests_where_unshifted_may_agree(
        g, "r1c1", views, dz, np.isfinite(d), box, ref_y
    )
    lumas = {n: np.asarray(g.images[n] @ edge.LUMA, np.float32) for n in views}
    r_at, r_count = edge._disagreement(lumas, ref_y, g.offsets, "r1c1", views, dz, box)
    r_un, _ = edge._disagreement(lumas, ref_y, g.offsets, "r1c1", views, np.zeros_like(dz), box, seen_by=r_count)
    r_near = np.minimum(
        *(edge._disagreement(lumas, ref_y, g.offsets, "r1c1", views, np.full_like(dz, s), box, seen_by=r_count)[0]
          for s in (-1.0, 1.0))
    )  # fmt: skip
    tested = np.isfinite(unshifted) | (count > 0)
    assert not tested[~np.isfinite(d)].any()  # only the estimated pixels
    assert 0.05 < tested.mean() < 0.95, tested.mean()  # some left out, some tested: the comparison means something
    # nothing with an estimate left out that could agree unshifted
    assert (r_un[~tested & np.isfinite(d)] >= edge.AGREE_MARGIN).all()
    assert np.array_equal(count[tested], r_count[tested])
    assert (count[tested] < len(views)).any()  # the frame's edge: some views do not see some tested pixels
    for got, ref in ((at, r_at), (unshifted, r_un), (nearby, r_near)):
        both = tested & np.isfinite(ref)
        assert np.array_equal(np.isfinite(got[tested]), np.isfinite(ref[tested]))
        assert np.abs(got[both] - ref[both]).max() <= 1e-6
    fixed = {}
    for sparse in (True, False):
        edge.SPARSE = sparse
        try:
            fixed[sparse] = edge.sensor_fixed(g, "r1c1", views, d, (5.0, 20.0))
        finally:
            edge.SPARSE = True
    assert fixed[True][:5, :47].all()  # the pattern
    assert np.array_equal(fixed[True], fixed[False])



@pytest.mark.parametrize("rows", [1, 2, 7])
def test_the_sensor_tests_in_bands_of_rows_are_the_whole_boxs(monkeypatch: pytest.MonkeyPatch, rows: int) -> None:
    """Issue 24, the depth's peak: the sparse test samples the views in bands of rows (each with the row either
    side its 3x3 windows read), not the whole box at once. Bands of 1, 2 and 7 rows (band edges everywhere,
    the box's own edges among them) give the one-band values bit for bit."""
    from rigctl.depth import edge

    images = plane_with_overlay(10.0)
    g = grid_from_arrays(images, 1000.0, 0.12, 0.12 * 0.65)
    rng = np.random.default_rng(11)
    d = np.full(g.shape, 10.0, np.float32) + rng.normal(0, 0.4, g.shape).astype(np.float32)
    d[40:60, 50:90] = np.inf
    views = [n for n in g.names if n != "r1c1"]
    h, w = g.shape
    box = (3, h - 2, 1, w)  # the box's edges are not the frame's
    y0, y1, x0, x1 = box
    dz = np.where(np.isfinite(d), d, 0.0).astype(np.float32)[y0:y1, x0:x1]
    ref_y = np.asarray(g.images["r1c1"] @ edge.LUMA, np.float32)[y0:y1, x0:x1]
    have = np.isfinite(d)[y0:y1, x0:x1]
    monkeypatch.setattr(edge, "FIXED_BAND_ROWS", h)
    whole = edge._tests_where_unshifted_may_agree(g, "r1c1", views, dz, have, box, ref_y)
    monkeypatch.setattr(edge, "FIXED_BAND_ROWS", rows)
    banded = edge._tests_where_unshifted_may_agree(g, "r1c1", views, dz, have, box, ref_y)
    assert (whole[1] > 0).mean() > 0.05  # tested somewhere: the comparison means something
    for a, b in zip(whole, banded, strict=True):
        assert np.array_equal(a.view(np.uint32), b.view(np.uint32))


def _order_reference(grid, disparities):  # type: ignore[no-untyped-def]
    """The occlusion order as first written (issue 24 moved it to the box of each camera's estimates): every
    other view sampled over the whole frame, its non-finite values as -inf before sampling."""
    out = {}
    for a, d in disparities.items():
        flagged = np.zeros(d.shape, bool)
        have = np.isfinite(d)
        ox, oy = grid.offsets[a]
        others = [b for b in disparities if b != a and grid.offsets[b] != (ox, oy)]
        fixed = d
        if len(others) >= 2 and have.any():
            h, w = d.shape
            gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
            dz = np.where(have, d, 0.0).astype(np.float32)
            seen = []
            for b in others:
                rx, ry = grid.offsets[b][0] - ox, grid.offsets[b][1] - oy
                db = np.where(np.isfinite(disparities[b]), disparities[b], -np.inf).astype(np.float32)
                mx, my = gx - dz * np.float32(rx), gy - dz * np.float32(ry)
                border = {"borderMode": cv2.BORDER_CONSTANT, "borderValue": np.nan}
                seen.append(cv2.remap(db, mx, my, cv2.INTER_NEAREST, **border))
            stack = np.stack(seen)
            in_frame = ~np.isnan(stack)
            farther = in_frame & (stack < dz - 1.0)
            n_in, n_far = in_frame.sum(axis=0), farther.sum(axis=0)
            flagged = have & (n_in >= 2) & (2 * n_far > n_in)
            if flagged.any():
                seen_far = np.where(farther[:, flagged] & np.isfinite(stack[:, flagged]), stack[:, flagged], np.nan)
                some = np.isfinite(seen_far).any(axis=0)
                value = np.full(seen_far.shape[1], np.inf, np.float32)
                value[some] = np.nanmedian(seen_far[:, some], axis=0)
                fixed = d.copy()
                fixed[flagged] = value
        out[a] = (fixed, flagged)
    return out


@pytest.mark.parametrize(("seed", "rows"), [(0, 128), (1, 128), (2, 128), (0, 1), (1, 7), (2, 13)])
def test_the_occlusion_order_in_the_box_of_the_estimates_is_the_whole_frames(
    monkeypatch: pytest.MonkeyPatch, seed: int, rows: int
) -> None:
    """Issue 24: testing only the box of a camera's estimates, in bands of ``rows`` rows, changes nothing.
    Against the whole-frame reference, bit for bit: subjects touching the frame's edges (views sample outside
    the frame), a camera with no estimate, one with a single pixel, NaN where an estimate should be +inf
    (taken as the screen, as the reference does), the ``ORDER_TOL`` boundary hit exactly, and bands of 1, 7
    and 13 rows (flagged pixels in many bands, their values in the same order)."""
    from rigctl.depth import edge
    from rigctl.depth.edge import occlusion_order, ordered

    monkeypatch.setattr(edge, "ORDER_BAND_ROWS", rows)

    names = [f"r{r}c{c}" for r in range(3) for c in range(3)]
    grid = grid_from_arrays({n: np.zeros((60, 90, 3), np.float32) for n in names}, 1000.0, 0.12, 0.078)
    rng = np.random.default_rng(seed)
    disparities = {}
    for n in names:
        d = np.full((60, 90), np.inf, np.float32)
        y0, x0 = rng.integers(0, 30), rng.integers(0, 45)
        d[y0 : y0 + rng.integers(5, 60), x0 : x0 + rng.integers(5, 90)] = rng.choice([3.0, 4.0, 5.0, 8.0], 1)[0]
        d[rng.random(d.shape) < 0.05] = rng.uniform(0, 12)
        disparities[n] = d
    disparities["r0c0"][:] = np.inf  # no estimate at all
    disparities["r2c2"][:] = np.inf
    disparities["r2c2"][59, 89] = 6.0  # one pixel, in the corner
    disparities["r1c0"][rng.random((60, 90)) < 0.02] = np.nan
    disparities["r0c1"] = disparities["r0c1"].astype(np.float64)  # another type: sampled as float32, as before
    got, want = occlusion_order(grid, disparities), _order_reference(grid, disparities)
    assert sum(int(want[n][1].sum()) for n in names) > 50  # the scene does flag pixels
    if rows < 60:  # flagged pixels in several bands of a camera
        assert sum(len(np.unique(np.nonzero(want[n][1])[0] // rows)) > 1 for n in names) >= 3
    for n in names:
        assert np.array_equal(got[n][0], want[n][1])
        assert np.array_equal(ordered(disparities[n], *got[n]), want[n][0], equal_nan=True)
