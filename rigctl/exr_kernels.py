"""The EXR picture's per-pixel passes compiled (Numba): BT.709 code values to scene-linear light, premultiplied
by the matte clipped to [0, 1]. :func:`rigctl.exr.picture_reference` computes the same with numpy in seven
frame-sized passes and as many temporaries; these two passes around numpy's own power function (vectorised,
faster than any scalar one here, and the reference's: the results are the same bit for bit) read the picture
twice and write nothing but the outputs, over all cores (issue 24: the write's time and memory)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, fastmath=False)
def lifted(rgb: np.ndarray, out: np.ndarray, knee: float, lift: float, gain: float) -> None:  # pragma: no cover
    """``out`` = (max(v, knee) + lift) / gain of every code value ``v`` of ``rgb`` (H x W x 3), in float32: what
    the inverse OETF raises to 1 / 0.45 above the knee. NaN stays NaN, as numpy's maximum keeps it."""
    k, add, div = np.float32(knee), np.float32(lift), np.float32(gain)
    h, w = rgb.shape[0], rgb.shape[1]
    for y in prange(h):
        for x in range(w):
            for c in range(3):
                v = rgb[y, x, c]
                out[y, x, c] = ((k if v < k else v) + add) / div


@njit(parallel=True, cache=True, fastmath=False)
def premultiply(  # pragma: no cover  (compiled)
    rgb: np.ndarray, matte: np.ndarray, out: np.ndarray, alpha: np.ndarray, knee: float, slope: float
) -> None:
    """``alpha`` = ``matte`` clipped to [0, 1]; ``out`` (the powers above the knee) becomes the linear light,
    v / slope below the knee, times alpha; float32. A NaN matte or code value gives NaN, as in numpy's path."""
    k, s = np.float32(knee), np.float32(slope)
    zero, one = np.float32(0.0), np.float32(1.0)
    h, w = matte.shape
    for y in prange(h):
        for x in range(w):
            a = matte[y, x]
            a = zero if a < zero else (one if a > one else a)
            alpha[y, x] = a
            for c in range(3):
                v = rgb[y, x, c]
                out[y, x, c] = (v / s if v < k else out[y, x, c]) * a
