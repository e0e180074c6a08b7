"""The cost volume's per-level matching cost as one compiled pass (Numba, no Python objects inside): for every
view, the bilinear sample where the reference's pixel lies at a disparity (a per-pixel map), Hosni et al.'s
truncated intensity and gradient differences, the box aggregation, INVALID outside the view, and per pixel
the mean of the best ``keep`` views that see the point.

It computes what ``combine(MatchViews.view_costs(d, win), keep)`` computes with OpenCV and numpy (that path
stays the reference, ``tests/unit/test_cost_kernels.py`` asserts the two agree), without the eight
three-channel warped images, the (views, h, w) stack and ``np.partition`` along its first axis that made up
most of the ``best`` preset's time. The sample is exact bilinear with edges
replicated, as ``cv2.remap`` and ``cv2.warpAffine`` of OpenCV 5 compute it for float images. Parallel over
rows; ``cache=True`` keeps the machine code (only the first call on a machine compiles, a few seconds).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # waiting threads sleep (see rigctl/render/kernels.py)

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

F32 = NDArray[np.float32]
ROWS = 128  # rows per block of the per-view arrays (views x rows x width): a block's, not the crop's memory


@njit(parallel=True, cache=True, fastmath=False)
def _differences(
    levels: F32,
    ref: F32,
    rel: F32,
    d: F32,
    y0: int,
    x0: int,
    r: int,
    c_int: float,
    c_grad: float,
    tau_i: float,
    tau_g: float,
    ad: F32,
    outside: NDArray[np.bool_],
    org: NDArray[np.int64],
    fh: int,
    fw: int,
) -> None:
    """``ad`` (views, h, w): the truncated differences of each view sampled at disparity ``d`` (h, w), summed
    over ``2 r + 1`` columns; ``outside``: where the sample falls outside the view (its frame, ``fh`` x ``fw``).
    ``levels[v]`` is the part of view v whose top-left pixel is ``org[v]`` (y, x) in its frame, with one pixel
    around it (``feature_kernels.view_levels``)."""
    nv, hh, ww = levels.shape[0], levels.shape[1] - 2, levels.shape[2] - 2
    h, w = d.shape
    ci, cg = np.float32(c_int), np.float32(c_grad)
    ti, tg = np.float32(tau_i), np.float32(tau_g)
    for y in prange(h):
        row = np.empty(w, np.float32)
        xa, xb = np.empty(w, np.int64), np.empty(w, np.int64)
        ya, yb = np.empty(w, np.int64), np.empty(w, np.int64)
        fx, fy = np.empty(w, np.float32), np.empty(w, np.float32)
        gy = np.float32(y0 + y)
        for v in range(nv):
            rx, ry = rel[v, 0], rel[v, 1]
            oy, ox = org[v, 0], org[v, 1]
            # positions, weights and the outside test first (a loop the compiler vectorises), then the samples
            for x in range(w):
                mx = np.float32(x0 + x) - d[y, x] * rx
                my = gy - d[y, x] * ry
                outside[v, y, x] = (mx < 0) | (mx > fw - 1) | (my < 0) | (my > fh - 1)
                bx, by = np.floor(mx), np.floor(my)
                fx[x], fy[x] = mx - bx, my - by
                ix, iy = int(bx) - ox, int(by) - oy
                xa[x], xb[x] = min(max(ix, 0), ww - 1), min(max(ix + 1, 0), ww - 1)
                ya[x], yb[x] = min(max(iy, 0), hh - 1), min(max(iy + 1, 0), hh - 1)
            for x in range(w):
                ex, ey = fx[x], fy[x]
                w00 = (np.float32(1.0) - ey) * (np.float32(1.0) - ex)
                w01 = (np.float32(1.0) - ey) * ex
                w10 = ey * (np.float32(1.0) - ex)
                w11 = ey * ex
                s0, s1, s2 = sample3(levels, v, ya[x], yb[x], xa[x], xb[x], w00, w01, w10, w11)
                a = min(abs(s0 - ref[y, x, 0]), ti) * ci
                a += min(abs(s1 - ref[y, x, 1]) + abs(s2 - ref[y, x, 2]), tg) * cg
                row[x] = a
            _row_sums(row, r, ad[v, y])


@njit(parallel=True, cache=True, fastmath=False)
def _differences_at(
    levels: F32,
    ref: F32,
    shift: F32,
    r: int,
    c_int: float,
    c_grad: float,
    tau_i: float,
    tau_g: float,
    ad: F32,
    org: NDArray[np.int64],
    yoff: int,
) -> None:
    """``_differences`` at one disparity for every pixel: view v's sample for crop pixel (x, y) lies at
    (x + shift[v, 0], y + shift[v, 1]) (``warpAffine``'s translation), so the weights are one per view.
    ``ref`` and ``ad`` hold the crop's rows from ``yoff`` on."""
    nv, hh, ww = levels.shape[0], levels.shape[1] - 2, levels.shape[2] - 2
    h, w = ref.shape[0], ref.shape[1]
    ci, cg = np.float32(c_int), np.float32(c_grad)
    ti, tg = np.float32(tau_i), np.float32(tau_g)
    for y in prange(h):
        row = np.empty(w, np.float32)
        for v in range(nv):
            sx, sy = shift[v, 0], shift[v, 1]
            bx, by = np.floor(sx), np.floor(sy)
            fx, fy = np.float32(sx - bx), np.float32(sy - by)
            ox, iy = int(bx) - org[v, 1], y + yoff + int(by) - org[v, 0]
            ya, yb = min(max(iy, 0), hh - 1), min(max(iy + 1, 0), hh - 1)
            w00 = (np.float32(1.0) - fy) * (np.float32(1.0) - fx)
            w01 = (np.float32(1.0) - fy) * fx
            w10 = fy * (np.float32(1.0) - fx)
            w11 = fy * fx
            for x in range(w):
                xa, xb = min(max(x + ox, 0), ww - 1), min(max(x + ox + 1, 0), ww - 1)
                s0, s1, s2 = sample3(levels, v, ya, yb, xa, xb, w00, w01, w10, w11)
                a = min(abs(s0 - ref[y, x, 0]), ti) * ci
                a += min(abs(s1 - ref[y, x, 1]) + abs(s2 - ref[y, x, 2]), tg) * cg
                row[x] = a
            _row_sums(row, r, ad[v, y])


@njit(inline="always")
def sample3(
    levels: F32,
    v: int,
    ya: int,
    yb: int,
    xa: int,
    xb: int,
    w00: np.float32,
    w01: np.float32,
    w10: np.float32,
    w11: np.float32,
) -> tuple[np.float32, np.float32, np.float32]:
    # view v's intensity, d/dx and d/dy, bilinear between rows ya, yb and columns xa, xb of its part (the sums
    # in this order), each corner's derivatives made from ``levels`` (the part with one pixel around it,
    # ``feature_kernels.view_levels``) as ``view_features`` makes them: central differences halved
    a0, a1, b0, b1 = ya + 1, yb + 1, xa + 1, xb + 1
    i00, i01, i10, i11 = levels[v, a0, b0], levels[v, a0, b1], levels[v, a1, b0], levels[v, a1, b1]
    s0 = i00 * w00 + i01 * w01
    s0 += i10 * w10
    s0 += i11 * w11
    # a derivative is (right - left) * 0.5, then times its weight: the same as the difference times half the
    # weight (halving is exact), so each corner's product is the features' bit for bit
    half = np.float32(0.5)
    h00, h01, h10, h11 = w00 * half, w01 * half, w10 * half, w11 * half
    # inside the part the two columns (rows) are neighbours, so half of the derivatives' samples are the
    # corners already read: the same values, read once (12 reads instead of 20); at a clamped edge all twenty
    if b1 == b0 + 1:
        s1 = (i01 - levels[v, a0, b0 - 1]) * h00 + (levels[v, a0, b1 + 1] - i00) * h01
        s1 += (i11 - levels[v, a1, b0 - 1]) * h10
        s1 += (levels[v, a1, b1 + 1] - i10) * h11
    else:
        s1 = (levels[v, a0, b0 + 1] - levels[v, a0, b0 - 1]) * h00
        s1 += (levels[v, a0, b1 + 1] - levels[v, a0, b1 - 1]) * h01
        s1 += (levels[v, a1, b0 + 1] - levels[v, a1, b0 - 1]) * h10
        s1 += (levels[v, a1, b1 + 1] - levels[v, a1, b1 - 1]) * h11
    if a1 == a0 + 1:
        s2 = (i10 - levels[v, a0 - 1, b0]) * h00 + (i11 - levels[v, a0 - 1, b1]) * h01
        s2 += (levels[v, a1 + 1, b0] - i00) * h10
        s2 += (levels[v, a1 + 1, b1] - i01) * h11
    else:
        s2 = (levels[v, a0 + 1, b0] - levels[v, a0 - 1, b0]) * h00
        s2 += (levels[v, a0 + 1, b1] - levels[v, a0 - 1, b1]) * h01
        s2 += (levels[v, a1 + 1, b0] - levels[v, a1 - 1, b0]) * h10
        s2 += (levels[v, a1 + 1, b1] - levels[v, a1 - 1, b1]) * h11
    return s0, s1, s2


@njit(inline="always")
def _row_sums(row: F32, r: int, out: F32) -> None:
    # the box's horizontal sums (the vertical ones are taken in ``_aggregate``), each added from 0 in the order
    # dx = -r..r; the columns whose window lies inside the row without the reflection's branches
    w = row.shape[0]
    inner_a, inner_b = min(r, w), max(min(r, w), w - r)
    for x in range(inner_a):
        out[x] = _reflected_sum(row, x, r, w)
    for x in range(inner_a, inner_b):
        acc = np.float32(0.0)
        for dx in range(-r, r + 1):
            acc += row[x + dx]
        out[x] = acc
    for x in range(inner_b, w):
        out[x] = _reflected_sum(row, x, r, w)


@njit(inline="always")
def _reflected_sum(row: F32, x: int, r: int, w: int) -> np.float32:
    acc = np.float32(0.0)
    for dx in range(-r, r + 1):
        acc += row[_reflect(x + dx, w)]
    return acc


@njit(inline="always")
def vertical_sum(dst: NDArray[np.floating], src: F32, v: int, y: int, r: int, r101: bool, h: int, a0: int) -> None:
    # dst[x] = the sum of src[v, y + dy, x] for dy = -r..r, added in that order from 0, rows beyond the edge
    # (of h rows) reflected as OpenCV's BORDER_REFLECT_101 (r101) or BORDER_REFLECT; src holds rows from a0 on
    dst[:] = 0.0
    for dy in range(-r, r + 1):
        row = src[v, (reflect101(y + dy, h) if r101 else _reflect(y + dy, h)) - a0]
        for x in range(dst.shape[0]):
            dst[x] += row[x]


@njit(inline="always")
def _reflect(i: int, n: int) -> int:
    # OpenCV's BORDER_REFLECT (fedcba|abcdef), for a window no wider than the image
    if i < 0:
        return -i - 1
    if i >= n:
        return 2 * n - i - 1
    return i


@njit(inline="always")
def reflect101(i: int, n: int) -> int:
    # OpenCV's default border (gfedcb|abcdefgh|gfedcba)
    if n == 1:
        return 0
    if i < 0:
        return -i
    if i >= n:
        return 2 * n - 2 - i
    return i


@njit(parallel=True, cache=True, fastmath=False)
def _aggregate(
    ad: F32, outside: NDArray[np.bool_], win: int, keep: int, invalid: float, out: F32, first: int, h: int, a0: int
) -> None:
    """``out`` (rows ``first`` on of h): per pixel the mean of the ``keep`` smallest box-aggregated view
    costs, among the views that see the point (INVALID where none does). ``ad`` and ``outside`` hold the
    rows from ``a0`` on, the window's rows around ``out``'s included."""
    nv, w = ad.shape[0], ad.shape[2]
    r = win // 2
    inv = np.float32(invalid)
    half = np.float32(invalid * 0.5)
    norm = np.float32(1.0 / (win * win))
    k = min(keep, nv)
    for yo in prange(out.shape[0]):
        y = first + yo
        costs = np.empty((nv, w), np.float32)
        rank = np.empty(w, np.int32)
        total = np.zeros(w, np.float32)
        n = np.zeros(w, np.int32)
        for v in range(nv):
            cv = costs[v]
            vertical_sum(cv, ad, v, y, r, False, h, a0)
            for x in range(w):
                cv[x] = inv if outside[v, y - a0, x] else cv[x] * norm
        # the keep smallest, branch-free: a view is kept where fewer than keep views rank before it (ties by
        # view order); the seen ones among them are averaged
        for i in range(nv):
            ci = costs[i]
            rank[:] = 0
            for j in range(nv):
                cj = costs[j]
                if j < i:
                    for x in range(w):
                        rank[x] += cj[x] <= ci[x]
                elif j > i:
                    for x in range(w):
                        rank[x] += cj[x] < ci[x]
            for x in range(w):
                use = (rank[x] < k) & (ci[x] < half)
                total[x] += ci[x] if use else np.float32(0.0)
                n[x] += use
        for x in range(w):
            out[yo, x] = total[x] / np.float32(n[x]) if n[x] > 0 else inv


def combined_costs(
    levels: F32,
    ref: F32,
    rel: NDArray[np.float64],
    d: float | F32,
    origin: tuple[int, int],
    win: int,
    keep: int,
    weights: tuple[float, float, float, float],
    invalid: float,
    org: NDArray[np.int64] | None = None,
    frame: tuple[int, int] | None = None,
    active: NDArray[np.bool_] | None = None,
) -> F32:
    """(h, w) combined cost at the disparity ``d`` (a number or an (h, w) map): ``levels`` (views, H + 2, W + 2) the
    views' intensity with a pixel around it (``feature_kernels.view_levels``; their gradients are made from it),
    ``ref`` (h, w, 3) the reference crop whose top-left pixel is ``origin`` (y, x) in the views, ``rel`` (views, 2)
    the baselines, ``weights`` the intensity and gradient scale and truncation. At a number, samples and the outside
    test are placed as ``MatchViews.warp`` places them (``warpAffine``'s float32 translation; the test in double
    precision). ``levels[v]`` may be a part of view v: its top-left pixel at ``org[v]`` (y, x) in the view's
    ``frame`` (h, w) (default: the whole view). ``active`` (h, w): only these pixels are wanted; each block of rows
    is computed on the columns its active pixels and their windows span (the same values there, bit for bit),
    ``invalid`` beside them."""
    nv = levels.shape[0]
    hh, ww = frame if frame is not None else (levels.shape[1] - 2, levels.shape[2] - 2)
    org = np.zeros((nv, 2), np.int64) if org is None else np.ascontiguousarray(org, np.int64)
    h, w = ref.shape[0], ref.shape[1]
    y0, x0 = origin
    r = win // 2
    out = np.empty((h, w), np.float32)
    shift = np.empty((nv, 2), np.float32)
    if isinstance(d, float):
        for v in range(nv):
            shift[v] = (x0 - d * float(rel[v, 0]), y0 - d * float(rel[v, 1]))
    dm = None if isinstance(d, float) else np.ascontiguousarray(d, np.float32)
    rel32 = rel.astype(np.float32)
    # in blocks of rows (each with the window's rows around it): the per-view differences are a block's, not
    # the crop's (issue 24: memory), and every row is computed as in one pass
    for a in range(0, h, ROWS):
        b = min(h, a + ROWS)
        a0, b0 = max(0, a - r), min(h, b + r)
        ca, cb = (0, w) if active is None else block_columns(active, a, b, r)
        out[a:b, :ca] = out[a:b, cb:] = invalid
        if cb <= ca:
            continue
        # the block's columns ca..cb, the same samples (at a number the shift is the crop's: the views' parts
        # are moved by ca instead, exact in integers)
        ad = np.empty((nv, b0 - a0, cb - ca), np.float32)
        outside = np.empty((nv, b0 - a0, cb - ca), bool)
        ref_b = np.ascontiguousarray(ref[a0:b0, ca:cb])
        if dm is None:
            assert isinstance(d, float)
            for v in range(nv):
                rx, ry = float(rel[v, 0]), float(rel[v, 1])
                xs = np.arange(x0, x0 + w, dtype=np.float32)[ca:cb] - d * rx
                ys = np.arange(y0 + a0, y0 + b0, dtype=np.float32) - d * ry
                outside[v] = ((ys < 0) | (ys > hh - 1))[:, None] | ((xs < 0) | (xs > ww - 1))[None, :]
            org_c = org - np.array([0, ca], np.int64)
            _differences_at(levels, ref_b, shift.astype(np.float64), r, *weights, ad, org_c, a0)
        else:
            d_b = np.ascontiguousarray(dm[a0:b0, ca:cb])
            _differences(levels, ref_b, rel32, d_b, y0 + a0, x0 + ca, r, *weights, ad, outside, org, hh, ww)
        if ca == 0 and cb == w:
            _aggregate(ad, outside, win, keep, invalid, out[a:b], a, h, a0)
        else:
            part = np.empty((b - a, cb - ca), np.float32)
            _aggregate(ad, outside, win, keep, invalid, part, a, h, a0)
            out[a:b, ca:cb] = part
    return out


def block_columns(active: NDArray[np.bool_], a: int, b: int, r: int) -> tuple[int, int]:
    """The columns [ca, cb) that rows a..b of ``combined_costs`` are computed on (with the window's rows
    around them): those of the rows' active pixels and ``r`` more either side (their windows)."""
    w = active.shape[1]
    cols = np.flatnonzero(active[a:b].any(axis=0))
    if cols.size == 0:
        return 0, 0
    return max(0, int(cols[0]) - r), min(w, int(cols[-1]) + 1 + r)


def computed_pixels(active: NDArray[np.bool_] | None, shape: tuple[int, int], win: int) -> int:
    """How many pixels ``combined_costs`` computes with ``active`` (for the report's pixel-levels)."""
    h, w = shape
    if active is None:
        return h * w
    total = 0
    for a in range(0, h, ROWS):
        ca, cb = block_columns(active, a, min(h, a + ROWS), win // 2)
        total += (min(h, a + ROWS) - a) * max(0, cb - ca)
    return total


@njit(parallel=True, cache=True, fastmath=False)
def _better_half(stack: F32, seen_by: F32, limit: bool, mean: F32, count: F32) -> None:
    h, w, nv = stack.shape
    for y in prange(h):
        buf = np.empty(nv, np.float32)
        for x in range(w):
            n = 0
            for v in range(nv):  # insertion sort of the few views (inf, unseen, last)
                val = stack[y, x, v]
                j = v
                while j > 0 and buf[j - 1] > val:
                    buf[j] = buf[j - 1]
                    j -= 1
                buf[j] = val
                n += np.isfinite(val)
            c = np.float32(n)
            views = min(c, seen_by[y, x]) if limit else c
            keep = max(1, int(np.floor((views + np.float32(1.0)) / np.float32(2.0))))
            acc = np.float32(0.0)
            for v in range(keep):
                acc += buf[v] if np.isfinite(buf[v]) else np.float32(0.0)
            mean[y, x] = np.float32(np.float64(acc) / np.float64(keep)) if views > 0 else np.float32(np.inf)
            count[y, x] = c


def better_half_mean(stack: F32, seen_by: F32 | None = None) -> tuple[F32, F32]:
    """Per pixel of an (h, w, views) stack of differences (inf: the view does not see it): the mean of its
    better half (the smallest ceil(n / 2) of the n seen, n at most ``seen_by``), inf where none is seen, and
    n. What ``edge._better_half_reference`` computes with a sort and a running sum over the views (the
    same sums in the same order, so the same bits; ``tests/unit/test_cost_kernels.py``)."""
    h, w, _ = stack.shape
    mean = np.empty((h, w), np.float32)
    count = np.empty((h, w), np.float32)
    limit = seen_by is not None
    seen = np.ascontiguousarray(seen_by if seen_by is not None else np.zeros((h, w), np.float32), np.float32)
    _better_half(np.ascontiguousarray(stack, np.float32), seen, limit, mean, count)
    return mean, count
