"""OpenCV's semi-global matcher on one neighbouring pair of a rectified grid (flipped and transposed so every
pair is a left-right pair), as disparity of the horizontal spacing for the reference camera. The OpenCV
baselines use it alone; the ``best`` preset uses it per pair and then fuses the pairs with every view."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from rigctl.depth.grid import Grid

F32 = NDArray[np.float32]
BLOCK = 3


def make_sgbm(lo: float, hi: float, block: int = BLOCK) -> cv2.StereoSGBM:
    min_d = math.floor(lo)
    num = max(16, math.ceil((hi - min_d + 1) / 16.0) * 16)
    return cv2.StereoSGBM.create(
        minDisparity=min_d,
        numDisparities=num,
        blockSize=block,
        P1=8 * 3 * block * block,
        P2=32 * 3 * block * block,
        uniquenessRatio=10,
        speckleWindowSize=100,
        speckleRange=2,
        disp12MaxDiff=1,
        mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    )


def _to_float(raw: NDArray[Any], matcher: cv2.StereoSGBM) -> F32:
    d = raw.astype(np.float32) / 16.0
    d[raw < (matcher.getMinDisparity() - 1) * 16 + 16] = np.inf  # OpenCV marks "no estimate" below the range
    return d


def neighbour(grid: Grid, ref: str, dx: int, dy: int) -> str | None:
    """The nearest camera from ``ref`` in direction (dx, dy) along a row or a column, if there is one."""
    ox, oy = grid.offsets[ref]
    best, best_dist = None, math.inf
    for n in grid.names:
        rx, ry = grid.offsets[n][0] - ox, grid.offsets[n][1] - oy
        along, across = (rx * dx, ry) if dy == 0 else (ry * dy, rx)
        if along > 1e-6 and abs(across) < 0.25 * along and along < best_dist:
            best, best_dist = n, along
    return best


def _capped(d_range: tuple[float, float], scale: float, extent: int) -> tuple[float, float] | None:
    """The pair's search range in its own pixels, no wider than the image it searches (a wider range cannot
    match anything, and OpenCV fails when its levels, in steps of 16, reach the image width); None when not
    even 16 levels fit. A negative minimum no further than the image allows either (OpenCV asserts that the
    columns left to match, ``extent + min(lo, 0) - max(lo + levels, 0)``, are not empty)."""
    lo, hi = max(d_range[0] * scale, BLOCK + 1.0 - extent), d_range[1] * scale
    room = ((extent - BLOCK - 1 - max(math.floor(lo), 0)) // 16) * 16  # a positive minimum shifts the search
    if room < 16 or hi < lo:
        return None
    return lo, min(hi, math.floor(lo) + room - 1)


PATH_MARGIN = 64  # px beyond the reach the matcher sees: its paths along the line start that far out


def _reach(span: tuple[int, int], rel: float, d_range: tuple[float, float], extent: int) -> tuple[int, int]:
    """The stretch of a line (of ``extent`` px) a pair matches the ``span`` of the reference on: the span and
    where its points lie in the other camera (at ``rel`` spacings along the line) for every disparity of the
    range, grown by PATH_MARGIN, inside the image. The same disparities as on the whole line, except near
    where the matcher's paths now start (PATH_MARGIN away)."""
    ends = [span[0] - d * rel for d in d_range] + [span[1] - d * rel for d in d_range]
    lo = min(float(span[0]), *ends)
    hi = max(float(span[1]), *ends)
    return max(0, math.floor(lo) - PATH_MARGIN), min(extent, math.ceil(hi) + PATH_MARGIN)


def nan_median(stack: F32) -> tuple[F32, F32]:
    """Median over axis 0 of what is finite (NaN and infinities ignored), and the spread (largest minus
    smallest); NaN where nothing is finite. Compiled: each pixel's few layers sorted in registers, one pass
    (issue 24); :func:`nan_median_reference` is the numpy form it matches bit for bit."""
    layers = np.ascontiguousarray(stack, dtype=np.float32)
    med = np.empty(layers.shape[1:], np.float32)
    spread = np.empty(layers.shape[1:], np.float32)
    if layers.shape[0] and med.size:
        _median_spread(layers.reshape(layers.shape[0], -1), med.reshape(-1), spread.reshape(-1))
    else:
        med[...] = np.nan
        spread[...] = np.nan
    return med, spread


@njit(parallel=True, cache=True, fastmath=False)
def _median_spread(layers: F32, med: F32, spread: F32) -> None:
    n, size = layers.shape
    for start in prange((size + 4095) // 4096):
        buf = np.empty(n, np.float32)
        for p in range(start * 4096, min(size, start * 4096 + 4096)):
            k = 0
            for i in range(n):
                v = layers[i, p]
                if np.isfinite(v):  # insertion into the sorted finite values
                    j = k
                    while j > 0 and buf[j - 1] > v:
                        buf[j] = buf[j - 1]
                        j -= 1
                    buf[j] = v
                    k += 1
            if k == 0:
                med[p] = np.float32(np.nan)
                spread[p] = np.float32(np.nan)
            else:
                med[p] = np.float32(0.5) * (buf[(k - 1) // 2] + buf[k // 2])
                spread[p] = buf[k - 1] - buf[0]


def nan_median_reference(stack: F32) -> tuple[F32, F32]:
    """:func:`nan_median` in numpy: the few layers sorted by compare-and-swap over whole images (odd-even
    transposition), many times faster than ``np.nanmedian`` (masked arrays) or a sort along a strided axis."""
    layers = [np.where(np.isfinite(x), x, np.float32(np.inf)).astype(np.float32) for x in stack]
    n = len(layers)
    for p in range(n):
        for i in range(p % 2, n - 1, 2):
            lo, hi = np.minimum(layers[i], layers[i + 1]), np.maximum(layers[i], layers[i + 1])
            layers[i], layers[i + 1] = lo, hi
    srt = np.stack(layers)
    k = np.isfinite(srt).sum(0)
    lo_i = np.clip((k - 1) // 2, 0, None)[None]
    hi_i = np.clip(k // 2, 0, None)[None]
    med = 0.5 * (np.take_along_axis(srt, lo_i, 0)[0] + np.take_along_axis(srt, hi_i, 0)[0])
    top = np.take_along_axis(srt, np.clip(k - 1, 0, None)[None], 0)[0]
    none = k == 0
    with np.errstate(invalid="ignore"):
        spread = np.where(none, np.nan, top - srt[0])
    med = np.where(none, np.nan, med)
    return np.asarray(med, np.float32), np.asarray(spread, np.float32)


def _flipped(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """``image[:, ::-1]`` as a new array (OpenCV's flip: the same bytes as numpy's strided copy, faster)."""
    return np.asarray(cv2.flip(image, 1), np.uint8)


def pair_disparity(
    grid: Grid,
    ref: str,
    other: str,
    d_range: tuple[float, float],
    block: int = BLOCK,
    box: tuple[int, int, int, int] | None = None,
    u8: dict[str, NDArray[np.uint8]] | None = None,
    searched: list[int] | None = None,
    work: list[int] | None = None,
) -> F32:
    """SGBM between ``ref`` and one neighbour, returned as disparity of the horizontal spacing for ``ref``.
    ``box`` (y0, y1, x0, x1): only that part of ``ref`` is wanted; a horizontal pair then matches only those
    rows, and of them the columns its matches can reach (``_reach``), a vertical pair likewise. ``searched``
    and ``work`` collect the levels searched and the pixel-levels the matcher evaluated."""
    rx = grid.offsets[other][0] - grid.offsets[ref][0]
    ry = grid.offsets[other][1] - grid.offsets[ref][1]
    h, w = grid.shape
    y0, y1, x0, x1 = box if box is not None else (0, h, 0, w)
    if u8 is None:
        u8 = {}
    for n in (ref, other):  # 8-bit BGR as the grid holds it (made once when it came as float)
        if n not in u8:
            u8[n] = grid.bgr8(n)
    a, b = u8[ref], u8[other]
    horizontal = abs(ry) < abs(rx)
    # only the lines through the box (a horizontal pair its rows, a vertical one its columns), and along them
    # only the stretch the box's matches reach, with a margin for the matcher's paths (issue 24)
    if horizontal:
        c0, c1 = _reach((x0, x1), rx, d_range, w)
        a, b = a[y0:y1, c0:c1], b[y0:y1, c0:c1]
    else:
        c0, c1 = _reach((y0, y1), ry, d_range, h)
        a, b = a[c0:c1, x0:x1], b[c0:c1, x0:x1]
    # the copies by OpenCV (flip, transpose): the same bytes as numpy's strided copies, ten times faster
    if horizontal:  # horizontal: the other camera to the right is the "right" image
        scale = abs(rx)
        flip = rx < 0
        a, b = (_flipped(a), _flipped(b)) if flip else (np.ascontiguousarray(a), np.ascontiguousarray(b))
        rng = _capped(d_range, scale, a.shape[1])
        if rng is None:
            return np.full((y1 - y0, x1 - x0), np.inf, np.float32)
        m = make_sgbm(*rng, block)
        d = _to_float(m.compute(a, b), m)
        d = d[:, ::-1] if flip else d
    else:  # vertical: transposed, the camera below is the "right" image
        scale = abs(ry)
        flip = ry < 0
        a, b = np.asarray(cv2.transpose(a), np.uint8), np.asarray(cv2.transpose(b), np.uint8)
        if flip:
            a, b = _flipped(a), _flipped(b)
        rng = _capped(d_range, scale, a.shape[1])
        if rng is None:
            return np.full((y1 - y0, x1 - x0), np.inf, np.float32)
        m = make_sgbm(*rng, block)
        d = _to_float(m.compute(a, b), m)
        d = (d[:, ::-1] if flip else d).T
    d = d[:, x0 - c0 : x1 - c0] if horizontal else d[y0 - c0 : y1 - c0]
    if searched is not None:
        searched.append(int(m.getNumDisparities()))
    if work is not None:
        work.append(int(a.shape[0] * a.shape[1] * m.getNumDisparities()))
    return np.ascontiguousarray(d / np.float32(scale), dtype=np.float32)
