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


@njit(parallel=True, cache=True, fastmath=False)
def _differences(
    feats: F32,
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
) -> None:
    """``ad`` (views, h, w): the truncated differences of each view sampled at disparity ``d`` (h, w), summed
    over ``2 r + 1`` columns."""
    nv, hh, ww = feats.shape[0], feats.shape[1], feats.shape[2]
    h, w = d.shape
    ci, cg = np.float32(c_int), np.float32(c_grad)
    ti, tg = np.float32(tau_i), np.float32(tau_g)
    for y in prange(h):
        row = np.empty(w, np.float32)
        gy = np.float32(y0 + y)
        for v in range(nv):
            rx, ry = rel[v, 0], rel[v, 1]
            for x in range(w):
                mx = np.float32(x0 + x) - d[y, x] * rx
                my = gy - d[y, x] * ry
                ix, iy = int(mx), int(my)  # floor: truncation, one less below zero
                ix -= np.float32(ix) > mx
                iy -= np.float32(iy) > my
                fx, fy = mx - np.float32(ix), my - np.float32(iy)
                xa, xb = min(max(ix, 0), ww - 1), min(max(ix + 1, 0), ww - 1)
                ya, yb = min(max(iy, 0), hh - 1), min(max(iy + 1, 0), hh - 1)
                w00 = (np.float32(1.0) - fy) * (np.float32(1.0) - fx)
                w01 = (np.float32(1.0) - fy) * fx
                w10 = fy * (np.float32(1.0) - fx)
                w11 = fy * fx
                s0 = feats[v, ya, xa, 0] * w00 + feats[v, ya, xb, 0] * w01
                s0 += feats[v, yb, xa, 0] * w10
                s0 += feats[v, yb, xb, 0] * w11
                s1 = feats[v, ya, xa, 1] * w00 + feats[v, ya, xb, 1] * w01
                s1 += feats[v, yb, xa, 1] * w10
                s1 += feats[v, yb, xb, 1] * w11
                s2 = feats[v, ya, xa, 2] * w00 + feats[v, ya, xb, 2] * w01
                s2 += feats[v, yb, xa, 2] * w10
                s2 += feats[v, yb, xb, 2] * w11
                a = min(abs(s0 - ref[y, x, 0]), ti) * ci
                a += min(abs(s1 - ref[y, x, 1]) + abs(s2 - ref[y, x, 2]), tg) * cg
                row[x] = a
            # the box's horizontal sums (the vertical ones are taken in ``_aggregate``)
            for x in range(w):
                acc = np.float32(0.0)
                for dx in range(-r, r + 1):
                    acc += row[_reflect(x + dx, w)]
                ad[v, y, x] = acc


@njit(inline="always")
def _reflect(i: int, n: int) -> int:
    # OpenCV's BORDER_REFLECT (fedcba|abcdef), for a window no wider than the image
    if i < 0:
        return -i - 1
    if i >= n:
        return 2 * n - i - 1
    return i


@njit(parallel=True, cache=True, fastmath=False)
def _aggregate(
    ad: F32, rel: F32, d: F32, y0: int, x0: int, hh: int, ww: int, win: int, keep: int, invalid: float, out: F32
) -> None:
    """``out`` (h, w): per pixel the mean of the ``keep`` smallest box-aggregated view costs, among the views
    that see the point (INVALID where none does)."""
    nv, h, w = ad.shape
    r = win // 2
    inv = np.float32(invalid)
    half = np.float32(invalid * 0.5)
    norm = np.float32(1.0 / (win * win))
    for y in prange(h):
        costs = np.empty(nv, np.float32)
        for x in range(w):
            for v in range(nv):
                mx = np.float32(x0 + x) - d[y, x] * rel[v, 0]
                my = np.float32(y0 + y) - d[y, x] * rel[v, 1]
                if mx < 0 or mx > ww - 1 or my < 0 or my > hh - 1:
                    costs[v] = inv
                    continue
                acc = np.float32(0.0)
                for dy in range(-r, r + 1):
                    acc += ad[v, _reflect(y + dy, h), x]
                costs[v] = acc * norm
            # the keep smallest (insertion sort of a handful of values), the seen ones among them averaged
            for i in range(1, nv):
                c = costs[i]
                j = i - 1
                while j >= 0 and costs[j] > c:
                    costs[j + 1] = costs[j]
                    j -= 1
                costs[j + 1] = c
            total = np.float32(0.0)
            n = 0
            for i in range(min(keep, nv)):
                if costs[i] < half:
                    total += costs[i]
                    n += 1
            out[y, x] = total / np.float32(n) if n > 0 else inv


def combined_costs(
    feats: F32,
    ref: F32,
    rel: F32,
    d: F32,
    origin: tuple[int, int],
    win: int,
    keep: int,
    weights: tuple[float, float, float, float],
    invalid: float,
) -> F32:
    """(h, w) combined cost at the disparity map ``d`` (h, w): ``feats`` (views, H, W, 3) the views'
    intensity and gradients, ``ref`` (h, w, 3) the reference crop whose top-left pixel is ``origin`` (y, x) in
    the views, ``rel`` (views, 2) the baselines, ``weights`` the intensity and gradient scale and truncation."""
    nv, hh, ww = feats.shape[0], feats.shape[1], feats.shape[2]
    h, w = d.shape
    ad = np.empty((nv, h, w), np.float32)
    d = np.ascontiguousarray(d, np.float32)
    _differences(feats, ref, rel, d, origin[0], origin[1], win // 2, *weights, ad)
    out = np.empty((h, w), np.float32)
    _aggregate(ad, rel, d, origin[0], origin[1], hh, ww, win, keep, invalid, out)
    return out
