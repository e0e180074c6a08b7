"""The pair fusion's referee (``cost.SweepLevel.costs_where``) and the local normalisation of its views
(``cost.normalise_part``) as compiled passes (Numba). The referee: at the pixels where
the semi-global pairs disagree, each candidate disparity map's combined cost, sampled and summed at those
pixels' windows only.

The numpy form samples every view at the window pixels with ``cv2.remap``, scatters the truncated
differences into a crop-sized image and box-filters the whole crop, once per view and candidate (40 crop-sized
box filters a camera, most of the ``best`` preset's pair fusion at 3840x2160, where the pairs disagree on
half the subject). Here the samples are made at the window pixels only and each query pixel sums its own
window from them: the same samples (exact bilinear with edges
replicated, as ``cv2.remap`` of OpenCV 5 computes it for float images, at the same float32 positions), the
same window with the crop's edges reflected as ``cv2.boxFilter``'s BORDER_REFLECT, the same outside test and
the mean of the ``keep`` best views that see the point. The sums run in another order, so the costs agree
within float32 rounding (``tests/unit/test_referee_kernels.py`` holds them to the numpy form)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from rigctl.depth.cost_kernels import _reflect

F32 = NDArray[np.float32]


@njit(parallel=True, cache=True, fastmath=False)
def view_differences(
    norm: F32,
    org: tuple[float, float],
    rel: tuple[float, float],
    ref: F32,
    cand: F32,
    box_origin: tuple[int, int],
    ys: NDArray[np.intp],
    xs: NDArray[np.intp],
    truncate: float,
    out: F32,
) -> None:
    """``out[ys[i], xs[i]]`` (crop-sized; nothing else written): one view's (``norm``, its part whose top-left
    pixel is ``org`` (y, x) in its frame, at ``rel`` spacings) truncated difference from the reference crop
    ``ref`` at crop pixel (``ys[i]``, ``xs[i]``), sampled at that pixel's disparity in ``cand`` (crop-sized).
    ``box_origin``: the crop's top-left pixel (y, x) in the frame."""
    ph, pw = norm.shape
    py, px = np.float32(org[0]), np.float32(org[1])
    rx, ry = np.float32(rel[0]), np.float32(rel[1])
    y0, x0 = box_origin
    tr = np.float32(truncate)
    one = np.float32(1.0)
    for i in prange(ys.size):
        y, x = ys[i], xs[i]
        d = cand[y, x]
        mx = (np.float32(x + x0) - d * rx) - px
        my = (np.float32(y + y0) - d * ry) - py
        # a sample beyond the part's edge replicates it (as remap's border): held at a pixel past the edge, so
        # no position however far converts to an integer that overflows
        mx = min(max(mx, np.float32(-1.0)), np.float32(pw))
        my = min(max(my, np.float32(-1.0)), np.float32(ph))
        bx, by = np.floor(mx), np.floor(my)
        ex, ey = mx - bx, my - by
        ix, iy = int(bx), int(by)
        xa, xb = min(max(ix, 0), pw - 1), min(max(ix + 1, 0), pw - 1)
        ya, yb = min(max(iy, 0), ph - 1), min(max(iy + 1, 0), ph - 1)
        s = norm[ya, xa] * ((one - ey) * (one - ex)) + norm[ya, xb] * ((one - ey) * ex)
        s += norm[yb, xa] * (ey * (one - ex))
        s += norm[yb, xb] * (ey * ex)
        out[y, x] = min(abs(s - ref[y, x]), tr)


@njit(parallel=True, cache=True, fastmath=False)
def window_means(
    diff: F32,
    cand: F32,
    rel: tuple[float, float],
    frame: tuple[int, int],
    box_origin: tuple[int, int],
    qy: NDArray[np.intp],
    qx: NDArray[np.intp],
    win: int,
    invalid: float,
    out: F32,
) -> None:
    """``out[i]``: the mean of ``diff`` (crop-sized, made by :func:`view_differences` at the window's pixels)
    over the ``win`` x ``win`` window around crop pixel (``qy[i]``, ``qx[i]``), the crop's edges reflected as
    ``cv2.boxFilter``'s BORDER_REFLECT (reflected once: ``win`` odd and no wider than the crop, which the caller
    sees to); ``invalid`` where the query pixel's own sample, at its disparity in
    ``cand``, falls outside the view's frame (``frame``: h, w; the view at ``rel`` spacings)."""
    h, w = diff.shape
    r = win // 2
    rx, ry = np.float32(rel[0]), np.float32(rel[1])
    fh, fw = frame
    y0, x0 = box_origin
    norm_area = 1.0 / (win * win)
    for i in prange(qy.size):
        y, x = qy[i], qx[i]
        acc = 0.0  # in double, as OpenCV's box filter of float sums
        for dy in range(-r, r + 1):
            row = diff[_reflect(y + dy, h)]
            for dx in range(-r, r + 1):
                acc += row[_reflect(x + dx, w)]
        dq = cand[y, x]
        cx = (x + x0) - dq * rx
        cy = (y + y0) - dq * ry
        outside = (cx < 0) | (cx > fw - 1) | (cy < 0) | (cy > fh - 1)
        out[i] = np.float32(invalid) if outside else np.float32(acc * norm_area)


@njit(parallel=True, cache=True, fastmath=False)
def keep_best(per_view: F32, keep: int, invalid: float, out: F32) -> None:
    """``out[i]``: the mean of the ``keep`` smallest of ``per_view[:, i]`` that are below ``invalid / 2`` (a
    view that sees the point); ``invalid`` where none of them is (``cost.combine``)."""
    nv, n = per_view.shape
    k = min(keep, nv)
    half = np.float32(invalid * 0.5)
    for i in prange(n):
        buf = np.empty(nv, np.float32)
        for v in range(nv):  # insertion into the sorted costs
            c = per_view[v, i]
            j = v
            while j > 0 and buf[j - 1] > c:
                buf[j] = buf[j - 1]
                j -= 1
            buf[j] = c
        total = np.float32(0.0)
        seen = 0
        for v in range(k):
            if buf[v] < half:
                total += buf[v]
                seen += 1
        out[i] = total / np.float32(seen) if seen > 0 else np.float32(invalid)


@njit(parallel=True, cache=True, fastmath=False)
def normalised(g: F32, mean: F32, sq: F32, origin: tuple[int, int], norm: F32, std: F32) -> None:
    """``cost.normalise``'s arithmetic after its box sums, on the part of ``g`` whose top-left pixel is
    ``origin`` (y, x) and whose size is ``norm``'s: ``std = sqrt(max(sq - mean * mean, 0))`` and
    ``norm = (g - mean) / (std + 0.01)``, each a float32 operation rounded as numpy rounds it (the pair
    fusion's referee normalises nine views a camera; numpy's five passes and temporaries over each)."""
    oy, ox = origin
    eps = np.float32(0.01)
    zero = np.float32(0.0)
    for y in prange(norm.shape[0]):
        for x in range(norm.shape[1]):
            m = mean[y + oy, x + ox]
            s = np.sqrt(max(sq[y + oy, x + ox] - m * m, zero))
            std[y, x] = s
            norm[y, x] = (g[y + oy, x + ox] - m) / (s + eps)
