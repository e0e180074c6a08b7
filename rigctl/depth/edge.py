"""Where the subject ends: which pixels get a depth.

**Coverage at the edge.** The keyer's matte is a soft ramp of the green excess, which is not the share of the
pixel the subject covers, and the green excess comes from the chroma, which a 4:2:2 camera (every SDI
camera, and the simulator) shares between two neighbouring pixels: at a silhouette both pixels of a pair
look half green. Only the luma is per pixel. :func:`coverage` therefore estimates each edge pixel's
coverage as a two-colour mix along the luma, between the nearest pure subject and pure screen colours (the
mean of the matte's 1 and 0 pixels in a 5x5 window, as local foreground and background colours are taken
in Bayesian and closed-form matting), and falls back to the same mix along the green excess where the two
lumas are too close to tell apart. Depth is estimated where the coverage is at least
:data:`DEPTH_COVERAGE` (half the pixel: the pixel's centre is more likely on the subject than off it).

**Fixed to the sensor.** A pattern that sits at the same place in every camera (the simulator's burnt-in id,
a timecode overlay, dust on a sensor window) matches at zero disparity, outside the range of a subject in
front of the rig: :func:`sensor_fixed` marks the pixels whose views agree better unshifted than at the
estimated disparity, and better than one pixel of disparity either way (a match, not a flat patch that
agrees at any shift), with the flat parts of the same pattern joined to such pixels (hysteresis). They are
not part of the scene and get no depth; neither do the specks they leave.

**In front of what the others see.** A point a camera puts at disparity d is seen by every other camera at
d times its baseline away; there, the other camera's own estimate can be nearer (something occludes the
point from it) or the same, never farther: a farther surface cannot hide a nearer one. Where most of the
views that have the point in frame see something farther (or the screen), the camera has spread a nearer
surface over its neighbour (foreground fattening, 1-3 px beside every occluding edge of a window matcher):
:func:`occlusion_order` gives such a pixel the median of the farther disparities those views see, or no
depth when they all see the screen. A renderer warps such a pixel with the nearer surface's disparity and
puts it beside that surface's outline, on the screen.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.cost import F32
from rigctl.depth.cost_kernels import better_half_mean
from rigctl.depth.fixed_kernels import window_disagreements
from rigctl.depth.grid import Grid
from rigctl.keying import subject_box

COVERAGE_COMPILED = True  # coverage at the soft pixels by a compiled kernel; False: coverage_reference
DEPTH_COVERAGE = 0.5  # depth where the subject covers at least this share of the pixel
WINDOW = 2  # radius of the window the local subject and screen colours are taken from
MIN_LUMA_STEP = 0.03  # below this luma difference between subject and screen, the green excess decides
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)  # BT.709
COMPILED = True  # the better half's mean by the compiled kernel; False: the numpy reference
AGREE_MARGIN = 0.02  # how much better (mean absolute difference, 0..1) the views must agree unshifted
SPARSE = True  # the fixed-to-the-sensor tests only where the views may agree unshifted; False: the whole box


def _near_mean(values: F32, weight: F32) -> tuple[F32, F32]:
    """Mean of ``values`` over the window's pixels of weight 1, and how many there were."""
    k = (2 * WINDOW + 1, 2 * WINDOW + 1)
    num = cv2.boxFilter(values * weight, -1, k, normalize=False, borderType=cv2.BORDER_REPLICATE)
    den = cv2.boxFilter(weight, -1, k, normalize=False, borderType=cv2.BORDER_REPLICATE)
    return (num / np.maximum(den, 1e-6)).astype(np.float32), np.asarray(den, np.float32)


def _mix(value: F32, fg: F32, bg: F32) -> F32:
    step = fg - bg
    safe = np.where(np.abs(step) > 1e-6, step, np.float32(1.0))
    return np.asarray(np.clip((value - bg) / safe, 0.0, 1.0), np.float32)


def coverage(rgb: F32, matte: F32) -> F32:
    """The share of each pixel the subject covers: the matte where it is 0 or 1, the two-colour mix (luma,
    else green excess) on the soft edge between. An edge pixel with no pure subject or screen pixel in its
    window keeps the matte. Compiled at the soft pixels alone (``coverage_kernels.py``) unless
    ``COVERAGE_COMPILED`` is off or the picture is not float32 RGB; :func:`coverage_reference` is the numpy
    and OpenCV path."""
    if not COVERAGE_COMPILED or rgb.dtype != np.float32 or rgb.shape != (*matte.shape, 3):
        return coverage_reference(rgb, matte)
    from rigctl.depth.coverage_kernels import edge_coverage  # compiled on first use

    out = np.empty(matte.shape, np.float32)
    edge_coverage(rgb, np.asarray(matte, np.float32), LUMA, WINDOW, MIN_LUMA_STEP, out)
    return out


def coverage_reference(rgb: F32, matte: F32) -> F32:
    """:func:`coverage` over the whole frame: six box filters (the subject's and the screen's luma, green
    excess and count) and the mix at every pixel, the matte kept where it is not soft."""
    soft = (matte > 0) & (matte < 1)
    if not soft.any():
        return matte.copy()
    luma = np.asarray(rgb @ LUMA, np.float32)
    excess = np.asarray(rgb[..., 1] - np.maximum(rgb[..., 0], rgb[..., 2]), np.float32)
    solid, screen = (matte >= 1).astype(np.float32), (matte <= 0).astype(np.float32)
    y_f, n_f = _near_mean(luma, solid)
    y_b, n_b = _near_mean(luma, screen)
    s_f, _ = _near_mean(excess, solid)
    s_b, _ = _near_mean(excess, screen)
    both = soft & (n_f > 0) & (n_b > 0)
    by_luma = np.abs(y_f - y_b) >= MIN_LUMA_STEP
    # the screen is the uniform side: a luma away from the screen's is the subject's, on whichever side of
    # the screen's luma the nearby subject is (a two-colour mix |Y - Y_B| = c |Y_F - Y_B|)
    by_deviation = np.clip(np.abs(luma - y_b) / np.maximum(np.abs(y_f - y_b), 1e-6), 0.0, 1.0)
    mixed = np.where(by_luma, by_deviation, _mix(excess, s_f, s_b))
    return np.asarray(np.where(both, mixed, matte), np.float32)


def _disagreement(
    lumas: dict[str, F32],
    ref_y: F32,
    offsets: dict[str, tuple[float, float]],
    ref: str,
    views: list[str],
    shift: F32,
    box: tuple[int, int, int, int],
    seen_by: F32 | None = None,
) -> tuple[F32, F32]:
    """Per pixel of ``box``: the mean over the better half of the views that see it (sampled ``shift``
    disparity along their baseline, inside the image) of the 3x3 mean absolute luma difference between the
    reference and the view (inf where no view sees it), and how many views see it. ``seen_by``: use each
    pixel's better half of that many views, so two shifts are compared over the same number of views.
    ``lumas``: the views' luma and ``ref_y`` the reference's in ``box``, computed once for the calls of one
    camera (the same arithmetic as per call, so the same values)."""
    y0, y1, x0, x1 = box
    ox, oy = offsets[ref]
    gy, gx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    stack = np.empty((y1 - y0, x1 - x0, len(views)), np.float32)  # views last: one pixel's in one cache line
    for i, n in enumerate(views):
        dx, dy = offsets[n][0] - ox, offsets[n][1] - oy
        seen = cv2.remap(lumas[n], gx - shift * np.float32(dx), gy - shift * np.float32(dy), cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)  # fmt: skip
        diff = np.abs(seen - ref_y)
        outside = cv2.blur((seen < 0).astype(np.float32), (3, 3)) > 0
        stack[..., i] = np.where(outside, np.inf, cv2.blur(diff, (3, 3)))
    if COMPILED:
        return better_half_mean(stack, seen_by)
    return _better_half_reference(stack, seen_by)


def _better_half_reference(stack: F32, seen_by: F32 | None) -> tuple[F32, F32]:
    """``cost_kernels.better_half_mean`` with numpy: sorted views, their running sum."""
    stack = np.sort(stack, axis=-1)
    count = np.isfinite(stack).sum(axis=-1).astype(np.float32)
    n_views = count if seen_by is None else np.minimum(count, seen_by)
    keep = np.maximum(1, np.floor((n_views + 1) / 2)).astype(np.int64)
    csum = np.cumsum(np.where(np.isfinite(stack), stack, np.float32(0.0)), axis=-1)
    mean = np.take_along_axis(csum, (keep - 1)[..., None], axis=-1)[..., 0] / keep
    return np.asarray(np.where(n_views > 0, mean, np.inf), np.float32), count


def sensor_fixed(
    grid: Grid, ref: str, views: list[str], disparity: F32, d_range: tuple[float, float]
) -> NDArray[np.bool_]:
    """Estimated pixels of ``ref`` that the views show better unshifted than at their estimated disparity,
    when zero disparity lies outside the range (a subject in front of the rig): fixed to the sensor."""
    h, w = disparity.shape
    out = np.zeros((h, w), bool)
    have = np.isfinite(disparity)
    if d_range[0] <= 0.0 <= d_range[1] or not have.any() or not views:
        return out
    ys, xs = np.nonzero(have)
    box = (int(ys.min()), int(ys.max()) + 1, int(xs.min()), int(xs.max()) + 1)
    y0, y1, x0, x1 = box
    d = np.where(have[y0:y1, x0:x1], disparity[y0:y1, x0:x1], 0.0).astype(np.float32)
    ref_y = np.asarray(grid.frames.region(ref, slice(y0, y1), slice(x0, x1)) @ LUMA, np.float32)
    if SPARSE:
        at_estimate, count, unshifted, nearby = _tests_where_unshifted_may_agree(
            grid, ref, views, d, have[y0:y1, x0:x1], box, ref_y
        )
    else:
        lumas = {n: np.asarray(grid.images[n] @ LUMA, np.float32) for n in views}
        off = grid.offsets
        at_estimate, count = _disagreement(lumas, ref_y, off, ref, views, d, box)
        unshifted, _ = _disagreement(lumas, ref_y, off, ref, views, np.zeros_like(d), box, seen_by=count)
        # a match, not a flat patch that agrees at any shift: one pixel of disparity either way agrees worse
        nearby = np.minimum(
            *(
                _disagreement(lumas, ref_y, off, ref, views, np.full_like(d, step), box, seen_by=count)[0]
                for step in (-1.0, 1.0)
            )
        )
    seen = np.isfinite(at_estimate) & np.isfinite(unshifted) & have[y0:y1, x0:x1]
    weak = seen & (unshifted < AGREE_MARGIN) & (unshifted <= at_estimate)
    sure = weak & (unshifted + AGREE_MARGIN < nearby)
    # hysteresis: the sure pixels (a pattern's edges) and the flat parts of the same pattern joined to them
    n, labels = cv2.connectedComponents(weak.astype(np.uint8), connectivity=8)
    seeded = np.zeros(n, bool)
    seeded[np.unique(labels[sure])] = True
    seeded[0] = False
    out[y0:y1, x0:x1] = seeded[labels]
    return out


FIXED_BAND_ROWS = 128  # rows of the box sampled at once by the sparse test


def _tests_where_unshifted_may_agree(
    grid: Grid,
    ref: str,
    views: list[str],
    d: F32,
    have: NDArray[np.bool_],
    box: tuple[int, int, int, int],
    ref_y: F32,
) -> tuple[F32, F32, F32, F32]:
    """:func:`sensor_fixed`'s four disagreements (at the estimate, its count of views, unshifted, the nearer
    of one pixel either way), box-sized, only at pixels with an estimate (``have``, box-sized) that can agree
    unshifted (inf and count 0 elsewhere): the mean of
    its better half of views is at least its best single view's, so a pixel whose every view differs
    unshifted by AGREE_MARGIN or more is not tested (issue 24: about two thirds of the presenter's pixels).
    There the compiled kernel (``fixed_kernels.py``) samples each view, its luma made only where the samples
    reach; the reference's samples and means within float32 rounding (``tests/unit/test_edge.py``)."""
    y0, y1, x0, x1 = box
    bh, bw = y1 - y0, x1 - x0
    ox, oy = grid.offsets[ref]
    inf = np.float32(np.inf)
    h, w = grid.shape
    rel = np.array([(grid.offsets[n][0] - ox, grid.offsets[n][1] - oy) for n in views], np.float32).reshape(-1, 2)
    # each view's part: the box grown by the farthest shift along its offset and the window, in the frame
    reach = max(1.0, float(np.abs(d[have]).max(initial=0.0))) + 3.0
    parts = [_grown(box, reach * abs(float(rx)), reach * abs(float(ry)), h, w) for rx, ry in rel]
    ph = max((p[1] - p[0] for p in parts), default=1)
    pw = max((p[3] - p[2] for p in parts), default=1)
    org = np.array([(min(p[0], h - ph), min(p[2], w - pw)) for p in parts], np.int64).reshape(-1, 2)
    luma = np.empty((len(views), ph, pw), np.float32)
    best = np.full((bh, bw), inf, np.float32)
    for i, n in enumerate(views):
        py0, px0 = int(org[i, 0]), int(org[i, 1])
        luma[i] = grid.frames.region(n, slice(py0, py0 + ph), slice(px0, px0 + pw)) @ LUMA
        # unshifted: the view's own pixels (outside is impossible: the box lies in the frame, and in the part)
        unshifted = np.abs(luma[i, y0 - py0 : y1 - py0, x0 - px0 : x1 - px0] - ref_y)
        np.minimum(best, cv2.blur(unshifted, (3, 3)), out=best)
    cand = have & (best < AGREE_MARGIN * (1.0 + 1e-5))  # the slack: a mean of values at the bound may round below it
    mean = better_half_mean if COMPILED else _better_half_reference
    full = [np.full((bh, bw), v, np.float32) for v in (inf, 0.0, inf, inf, inf)]  # count's 0 second
    # in bands of rows, each with the row either side its windows read (at the box's own edges they reflect
    # there, as over the box): every value is the box's at once, the samples held per band, not per box
    # (issue 24: at 3840x2160 they were 0.6 GiB, the depth's peak)
    for r0 in range(0, bh, FIXED_BAND_ROWS):
        r1 = min(bh, r0 + FIXED_BAND_ROWS)
        s0, s1 = max(0, r0 - 1), min(bh, r1 + 1)
        band = np.zeros((s1 - s0, bw), bool)
        band[r0 - s0 : r1 - s0] = cand[r0:r1]
        if not band.any():
            continue
        stacks, cy, cx = window_disagreements(luma, org, (h, w), ref_y[s0:s1], d[s0:s1], rel, y0 + s0, x0, band)
        at, count = mean(stacks[0], None)
        for a, v in zip(full, [at, count] + [mean(st, count)[0] for st in stacks[1:]], strict=True):
            a[cy + s0, cx] = v[:, 0]
        del stacks
    return full[0], full[1], full[2], np.minimum(full[3], full[4])


def _grown(box: tuple[int, int, int, int], px: float, py: float, h: int, w: int) -> tuple[int, int, int, int]:
    y0, y1, x0, x1 = box
    return max(0, int(y0 - py)), min(h, int(np.ceil(y1 + py))), max(0, int(x0 - px)), min(w, int(np.ceil(x1 + px)))


ORDER_TOL = 1.0  # disparity (px of the horizontal spacing) by which another view must see the point farther


def occlusion_order(grid: Grid, disparities: dict[str, F32]) -> dict[str, tuple[NDArray[np.bool_], F32]]:
    """Per camera: the pixels that most other views see farther, and what to put there (the median of what
    they see, +inf where that is the screen), in :func:`ordered`'s form. Decided from every camera's
    disparity as given (none sees another's corrections). Only the box of the camera's estimates is tested
    (nothing outside it can be flagged), each other view sampled where the box's points fall in it, in bands
    of ORDER_BAND_ROWS rows (each pixel's test is its own: the same values as the box at once)."""
    screen = {b: _screen_far(d) for b, d in disparities.items()}
    out: dict[str, tuple[NDArray[np.bool_], F32]] = {}
    for a, d in disparities.items():
        flagged = np.zeros(d.shape, bool)
        out[a] = (flagged, np.zeros(0, np.float32))
        have_all = np.isfinite(d)
        box = subject_box(have_all, 0)
        others = [b for b in disparities if b != a and grid.offsets[b] != grid.offsets[a]]
        if len(others) < 2 or box is None:
            continue
        y0, y1, x0, x1 = box
        values = [
            _order_band(grid, a, others, screen, d, have_all, (r0, min(y1, r0 + ORDER_BAND_ROWS), x0, x1), flagged)
            for r0 in range(y0, y1, ORDER_BAND_ROWS)
        ]
        if flagged.any():
            out[a] = (flagged, np.concatenate(values).astype(np.float32))
    return out


ORDER_BAND_ROWS = 128  # rows of the box tested at once (issue 24: the views' samples of a 4K box were 0.3 GiB)


def _order_band(
    grid: Grid,
    a: str,
    others: list[str],
    screen: dict[str, F32],
    d: F32,
    have_all: NDArray[np.bool_],
    band: tuple[int, int, int, int],
    flagged: NDArray[np.bool_],
) -> F32:
    """:func:`occlusion_order` on the rows ``band`` of camera ``a``: sets ``flagged`` there and returns the
    values of its flagged pixels, in row order."""
    y0, y1, x0, x1 = band
    ox, oy = grid.offsets[a]
    have, dz = have_all[y0:y1, x0:x1], d[y0:y1, x0:x1]
    gy, gx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    dz = np.where(have, dz, 0.0).astype(np.float32)
    stack = np.empty((len(others), y1 - y0, x1 - x0), np.float32)
    for i, b in enumerate(others):
        rx, ry = grid.offsets[b][0] - ox, grid.offsets[b][1] - oy
        mx, my = gx - dz * np.float32(rx), gy - dz * np.float32(ry)
        # NaN: outside b's frame
        cv2.remap(
            screen[b], mx, my, cv2.INTER_NEAREST, dst=stack[i], borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan
        )
    np.copyto(stack, np.float32(-np.inf), where=np.isinf(stack))  # a view's screen: far
    in_frame = ~np.isnan(stack)
    farther = in_frame & (stack < dz - ORDER_TOL)
    n_in, n_far = in_frame.sum(axis=0), farther.sum(axis=0)
    inside = have & (n_in >= 2) & (2 * n_far > n_in)
    flagged[y0:y1, x0:x1] = inside
    if not inside.any():
        return np.zeros(0, np.float32)
    seen_far = np.where(farther[:, inside] & np.isfinite(stack[:, inside]), stack[:, inside], np.nan)
    some = np.isfinite(seen_far).any(axis=0)
    value = np.full(seen_far.shape[1], np.inf, np.float32)
    value[some] = np.nanmedian(seen_far[:, some], axis=0)
    return value


def _screen_far(d: F32) -> F32:
    """``d`` for sampling by another view: its NaN (not expected: no estimate is +inf) as -inf, so that after
    sampling NaN means outside the frame alone and every infinity is the screen, far."""
    d = np.asarray(d, np.float32)  # what remap writes into the float32 stack (another type: a new array)
    return np.where(np.isnan(d), np.float32(-np.inf), d).astype(np.float32) if np.isnan(d).any() else d


def ordered(d: F32, flagged: NDArray[np.bool_], value: F32) -> F32:
    """``d`` with :func:`occlusion_order`'s values at the flagged pixels (a copy; ``d`` itself when none)."""
    if not flagged.any():
        return d
    fixed = d.copy()
    fixed[flagged] = value
    return fixed
