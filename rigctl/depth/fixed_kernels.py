"""The fixed-to-the-sensor tests (``edge.sensor_fixed``) as one compiled pass over the pixels that can agree
unshifted: for each such pixel, each view and each of four disparities (the estimate, 0, -1, +1), the 3x3
mean absolute luma difference between the reference and the view sampled at that disparity along the view's
baseline, inf where a sample of the window falls outside the view.

It computes what ``edge._disagreement`` computes with ``cv2.remap`` (bilinear, a constant -1 outside the
frame, then "outside" where the sample is negative) and ``cv2.blur`` (3x3, reflected at the box's edge) over
the whole box, at those pixels only (the reference path stays, ``tests/unit/test_edge.py`` asserts the two
agree within float32 rounding). Parallel over the pixels; ``cache=True`` keeps the machine code.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # waiting threads sleep (see rigctl/render/kernels.py)

import cv2
import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@njit(cache=True, fastmath=False, inline="always")
def _sample(luma: F32, v: int, oy: int, ox: int, hh: int, ww: int, mx: np.float32, my: np.float32) -> np.float32:
    """Bilinear sample of view ``v`` at (mx, my) of its frame (``hh`` x ``ww``; ``luma[v]`` is the part whose
    top-left pixel is (oy, ox) there), every tap outside the frame -1 (OpenCV's remap of a float image with
    BORDER_CONSTANT -1)."""
    bx, by = np.floor(mx), np.floor(my)
    ex, ey = mx - bx, my - by
    ix, iy = int(bx), int(by)
    jx, jy = ix - ox, iy - oy
    one = np.float32(1.0)
    w00 = (one - ey) * (one - ex)
    w01 = (one - ey) * ex
    w10 = ey * (one - ex)
    w11 = ey * ex
    in_x0, in_x1 = 0 <= ix < ww, 0 <= ix + 1 < ww
    in_y0, in_y1 = 0 <= iy < hh, 0 <= iy + 1 < hh
    p00 = luma[v, jy, jx] if in_y0 and in_x0 else np.float32(-1.0)
    p01 = luma[v, jy, jx + 1] if in_y0 and in_x1 else np.float32(-1.0)
    p10 = luma[v, jy + 1, jx] if in_y1 and in_x0 else np.float32(-1.0)
    p11 = luma[v, jy + 1, jx + 1] if in_y1 and in_x1 else np.float32(-1.0)
    s = p00 * w00 + p01 * w01
    s += p10 * w10
    s += p11 * w11
    return s


@njit(cache=True, fastmath=False, inline="always")
def _reflect(i: int, n: int) -> int:
    """OpenCV's default border (BORDER_REFLECT_101): -1 is 1, n is n - 2."""
    if n == 1:
        return 0
    i = abs(i)
    return 2 * (n - 1) - i if i > n - 1 else i


SHIFTS = np.array([0.0, 0.0, -1.0, 1.0], np.float32)  # the estimate's place (per pixel), then 0, -1, +1


@njit(parallel=True, cache=True, fastmath=False)
def _differences(
    luma: F32,
    org: NDArray[np.int64],
    hh: int,
    ww: int,
    ref_y: F32,
    d: F32,
    rel: F32,
    y0: int,
    x0: int,
    ny: NDArray[np.int64],
    nx: NDArray[np.int64],
) -> F32:
    """(4, views, n): |view - reference| at box pixel (ny[j], nx[j]), the view sampled at each of the four
    disparities; inf where the sample is negative (a tap outside the frame)."""
    nv, n = luma.shape[0], ny.shape[0]
    out = np.empty((4, nv, n), np.float32)
    for j in prange(n):
        qy, qx = ny[j], nx[j]
        gx, gy = np.float32(x0 + qx), np.float32(y0 + qy)
        r = ref_y[qy, qx]
        for v in range(nv):
            rx, ry = rel[v, 0], rel[v, 1]
            oy, ox = org[v, 0], org[v, 1]
            for k in range(4):
                s = d[qy, qx] if k == 0 else SHIFTS[k]
                seen = _sample(luma, v, oy, ox, hh, ww, gx - s * rx, gy - s * ry)
                out[k, v, j] = np.float32(np.inf) if seen < 0 else abs(seen - r)
    return out


@njit(parallel=True, cache=True, fastmath=False)
def _window_means(diffs: F32, index: NDArray[np.int32], cy: NDArray[np.int64], cx: NDArray[np.int64]) -> F32:
    """(4, n, 1, views): the 3x3 mean of ``diffs`` around box pixel (cy[i], cx[i]) (inf if one is inf), the
    window reflected at the box's edge; ``index``: each box pixel's place in ``diffs``."""
    nk, nv = diffs.shape[0], diffs.shape[1]
    bh, bw = index.shape
    n = cy.shape[0]
    out = np.empty((nk, n, 1, nv), np.float32)
    for i in prange(n):
        at = np.empty(9, np.int64)
        m = 0
        for a in range(-1, 2):
            qy = _reflect(cy[i] + a, bh)
            for b in range(-1, 2):
                at[m] = index[qy, _reflect(cx[i] + b, bw)]
                m += 1
        for k in range(nk):
            for v in range(nv):
                acc = np.float32(0.0)
                for m in range(9):
                    acc += diffs[k, v, at[m]]
                out[k, i, 0, v] = acc / np.float32(9.0)
    return out


def window_disagreements(
    luma: F32,
    org: NDArray[np.int64],
    frame: tuple[int, int],
    ref_y: F32,
    d: F32,
    rel: F32,
    y0: int,
    x0: int,
    cand: NDArray[np.bool_],
) -> tuple[F32, NDArray[np.int64], NDArray[np.int64]]:
    """(4, n, 1, views) and the pixels' rows and columns in the box: at each ``cand`` pixel (box-sized mask,
    the box's top-left at (y0, x0) in the frame), the 3x3 mean of |view - reference| with view v sampled at
    the estimate ``d`` (each window pixel at its own), 0, -1 and +1 times its offset ``rel[v]``; inf where a
    window pixel's sample is negative (a tap outside the frame, ``frame`` (h, w)). ``luma[v]`` is the part of
    view v whose top-left pixel is ``org[v]`` (y, x): every tap inside the frame must lie in it. Each pixel
    of the candidates' windows is sampled once."""
    need = cv2.dilate(cand.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0  # (reflected windows stay inside)
    ny, nx = np.nonzero(need)
    index = np.full(cand.shape, -1, np.int32)
    index[ny, nx] = np.arange(ny.size, dtype=np.int32)
    diffs = _differences(luma, org, frame[0], frame[1], ref_y, d, rel, y0, x0, ny, nx)
    cy, cx = np.nonzero(cand)
    return _window_means(diffs, index, cy, cx), cy, cx
