"""The cost volume's features of one view as one compiled pass (issue 24): intensity (the view's grey matched
to the reference's exposure, ``grey * gain + offset``), and its d/dx and d/dy as central differences halved,
reflected at the frame's edge, written interleaved into the view's place in the stack.

It computes what ``cost.features`` computes with OpenCV (``Sobel`` of ksize 1 and scale 0.5, BORDER_REFLECT,
then ``merge``) after numpy's ``g * gain + offset`` over the whole frame, bit for bit
(``tests/unit/test_feature_kernels.py``), without the frame-sized exposure-matched copy, the two derivative
images and the merge's pass. Parallel over rows; ``cache=True`` keeps the machine code.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # waiting threads sleep (see rigctl/render/kernels.py)

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@njit(cache=True, fastmath=False, inline="always")
def _level(g: F32, y: int, x: int, gain: np.float32, offset: np.float32, matched: bool) -> np.float32:
    """The view's intensity at (y, x): its grey, matched to the reference's exposure when ``matched`` (two
    roundings, as numpy's ``g * gain`` then ``+ offset``)."""
    v = g[y, x]
    if matched:
        v = v * gain
        v = v + offset
    return v


@njit(parallel=True, cache=True, fastmath=False)
def _features(g: F32, gain: np.float32, offset: np.float32, matched: bool, y0: int, x0: int, out: F32) -> None:
    h, w = g.shape
    for i in prange(out.shape[0]):
        y = y0 + i
        yu = y - 1 if y > 0 else 0  # BORDER_REFLECT: -1 is 0, h is h - 1
        yd = y + 1 if y < h - 1 else h - 1
        half = np.float32(0.5)
        for j in range(out.shape[1]):
            x = x0 + j
            xl = x - 1 if x > 0 else 0
            xr = x + 1 if x < w - 1 else w - 1
            out[i, j, 0] = _level(g, y, x, gain, offset, matched)
            dx = _level(g, y, xr, gain, offset, matched) - _level(g, y, xl, gain, offset, matched)
            dy = _level(g, yd, x, gain, offset, matched) - _level(g, yu, x, gain, offset, matched)
            out[i, j, 1] = dx * half
            out[i, j, 2] = dy * half


@njit(parallel=True, cache=True, fastmath=False)
def _levels(g: F32, gain: np.float32, offset: np.float32, matched: bool, y0: int, x0: int, out: F32) -> None:
    h, w = g.shape
    for i in prange(out.shape[0]):
        y = min(max(y0 - 1 + i, 0), h - 1)  # the row above and below the part, the frame's edge replicated
        for j in range(out.shape[1]):
            out[i, j] = _level(g, y, min(max(x0 - 1 + j, 0), w - 1), gain, offset, matched)


def view_levels(
    g: F32, part: tuple[int, int, int, int], out: F32 | None = None, exposure: tuple[float, float] | None = None
) -> F32:
    """(h + 2, w + 2) float32: the intensity of :func:`view_features` on ``part`` (y0, y1, x0, x1) of the whole
    grey ``g`` and one pixel around it, the frame's edges replicated (BORDER_REFLECT reaches one pixel as
    replication does): all the features are made of, so a kernel reading a part's features at a pixel makes
    them from it bit for bit (:func:`features_of_levels`, ``cost_kernels.sample3``) from a third of the
    memory (issue 24: the views' parts are most of a 4K estimate's working set). Into ``out`` when given."""
    y0, y1, x0, x1 = part
    if out is None:
        out = np.empty((y1 - y0 + 2, x1 - x0 + 2), np.float32)
    if out.size and g.size:
        gain, offset = exposure if exposure is not None else (1.0, 0.0)
        g32 = np.ascontiguousarray(g, dtype=np.float32)
        _levels(g32, np.float32(gain), np.float32(offset), exposure is not None, y0, x0, out)
    return out


def features_of_levels(levels: F32) -> F32:
    """(h, w, 3): the part's intensity, d/dx and d/dy (:func:`view_features`'s, bit for bit) from its
    :func:`view_levels` (h + 2, w + 2): central differences halved, the same two roundings."""
    half = np.float32(0.5)
    out = np.empty((levels.shape[0] - 2, levels.shape[1] - 2, 3), np.float32)
    out[..., 0] = levels[1:-1, 1:-1]
    out[..., 1] = (levels[1:-1, 2:] - levels[1:-1, :-2]) * half
    out[..., 2] = (levels[2:, 1:-1] - levels[:-2, 1:-1]) * half
    return out


def view_features(
    g: F32, part: tuple[int, int, int, int], out: F32 | None = None, exposure: tuple[float, float] | None = None
) -> F32:
    """(h, w, 3) float32: intensity, d/dx and d/dy on ``part`` (y0, y1, x0, x1) of the whole grey image ``g``,
    matched by ``exposure`` (gain, offset) when given; into ``out`` when given."""
    y0, y1, x0, x1 = part
    if out is None:
        out = np.empty((y1 - y0, x1 - x0, 3), np.float32)
    if out.size:
        gain, offset = exposure if exposure is not None else (1.0, 0.0)
        g32 = np.ascontiguousarray(g, dtype=np.float32)
        _features(g32, np.float32(gain), np.float32(offset), exposure is not None, y0, x0, out)
    return out
