"""The subject's coverage of each edge pixel (``edge.coverage``) compiled: the two-colour mix computed at the
soft pixels of the matte only (0 < matte < 1: a rim one to three pixels wide along the silhouette, under 1 %
of a presenter's frame), each from its own 5x5 window, instead of six box filters over the frame and the
mix at every pixel (issue 24: 0.3 s of a 4K camera's depth, for the few pixels that read it).

The window sums are taken directly, in float64, where ``cv2.boxFilter`` keeps running sums in float32: the
values agree with the numpy and OpenCV path (kept as ``edge.coverage_reference``) within float32 rounding,
which ``tests/unit/test_edge.py`` asserts (on finite pictures, as depth's are: a NaN spreads through a box
filter's running sums, here it stays in its own pixel); the frame's edge is replicated as there. Parallel over
rows."""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # waiting threads sleep (see rigctl/render/kernels.py)

import numpy as np
from numba import njit, prange


@njit(cache=True, fastmath=False, inline="always")
def _luma(rgb: np.ndarray, y: int, x: int, w0: float, w1: float, w2: float) -> float:  # pragma: no cover
    return w0 * rgb[y, x, 0] + w1 * rgb[y, x, 1] + w2 * rgb[y, x, 2]


@njit(cache=True, fastmath=False, inline="always")
def _excess(rgb: np.ndarray, y: int, x: int) -> float:  # pragma: no cover
    return rgb[y, x, 1] - max(rgb[y, x, 0], rgb[y, x, 2])


@njit(parallel=True, cache=True, fastmath=False)
def edge_coverage(  # pragma: no cover  (compiled)
    rgb: np.ndarray, matte: np.ndarray, luma: np.ndarray, radius: int, min_luma_step: float, out: np.ndarray
) -> None:
    """``out`` = ``matte``, but at each soft pixel (0 < matte < 1) whose window of ``radius`` (clamped to the
    frame) holds both a subject pixel (matte >= 1) and a screen pixel (matte <= 0): the share of the pixel the
    subject covers, from the windows' mean subject and screen luma (``luma``: the BT.709 weights) where they
    differ by ``min_luma_step`` or more, else from their mean green excess g - max(r, b)."""
    h, w = matte.shape
    w0, w1, w2 = luma[0], luma[1], luma[2]
    for y in prange(h):
        for x in range(w):
            a = matte[y, x]
            out[y, x] = a
            if not (a > 0 and a < 1):
                continue
            n_f = n_b = 0.0
            y_f = y_b = s_f = s_b = 0.0
            for dy in range(-radius, radius + 1):
                yy = min(max(y + dy, 0), h - 1)
                for dx in range(-radius, radius + 1):
                    xx = min(max(x + dx, 0), w - 1)
                    m = matte[yy, xx]
                    if m >= 1:
                        n_f += 1.0
                        y_f += _luma(rgb, yy, xx, w0, w1, w2)
                        s_f += _excess(rgb, yy, xx)
                    elif m <= 0:
                        n_b += 1.0
                        y_b += _luma(rgb, yy, xx, w0, w1, w2)
                        s_b += _excess(rgb, yy, xx)
            if n_f == 0 or n_b == 0:
                continue
            y_f, y_b, s_f, s_b = y_f / n_f, y_b / n_b, s_f / n_f, s_b / n_b
            if abs(y_f - y_b) >= min_luma_step:
                c = abs(_luma(rgb, y, x, w0, w1, w2) - y_b) / max(abs(y_f - y_b), 1e-6)
            else:
                step = s_f - s_b
                c = (_excess(rgb, y, x) - s_b) / (step if abs(step) > 1e-6 else 1.0)
            out[y, x] = min(max(c, 0.0), 1.0)
