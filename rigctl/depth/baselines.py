"""OpenCV baselines for ``rigctl bench depth``, measured on the same grids and disparity ranges as our presets:
SGBM 3WAY on the horizontal pair, SGBM with the WLS filter, and SGBM run on every neighbouring pair (left,
right, above, below: flipped and transposed so each is a left-right pair) and fused by the median."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import Grid

F32 = NDArray[np.float32]
BLOCK = 3


def _u8(img: F32) -> NDArray[np.uint8]:
    return np.ascontiguousarray(np.clip(img[..., ::-1] * 255 + 0.5, 0, 255).astype(np.uint8))


def _sgbm(lo: float, hi: float, block: int = BLOCK) -> cv2.StereoSGBM:
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


def pair_disparity(grid: Grid, ref: str, other: str, d_range: tuple[float, float], block: int = BLOCK) -> F32:
    """SGBM between ``ref`` and one neighbour, returned as disparity of the horizontal spacing for ``ref``."""
    rx = grid.offsets[other][0] - grid.offsets[ref][0]
    ry = grid.offsets[other][1] - grid.offsets[ref][1]
    a, b = _u8(grid.images[ref]), _u8(grid.images[other])
    if abs(ry) < abs(rx):  # horizontal: the other camera to the right is the "right" image
        scale = abs(rx)
        flip = rx < 0
        if flip:
            a, b = a[:, ::-1], b[:, ::-1]
        m = _sgbm(d_range[0] * scale, d_range[1] * scale, block)
        d = _to_float(m.compute(np.ascontiguousarray(a), np.ascontiguousarray(b)), m)
        d = d[:, ::-1] if flip else d
    else:  # vertical: transposed, the camera below is the "right" image
        scale = abs(ry)
        a, b = np.ascontiguousarray(a.transpose(1, 0, 2)), np.ascontiguousarray(b.transpose(1, 0, 2))
        flip = ry < 0
        if flip:
            a, b = a[:, ::-1], b[:, ::-1]
        m = _sgbm(d_range[0] * scale, d_range[1] * scale, block)
        d = _to_float(m.compute(np.ascontiguousarray(a), np.ascontiguousarray(b)), m)
        d = (d[:, ::-1] if flip else d).T
    return np.ascontiguousarray(d / np.float32(scale), dtype=np.float32)


def sgbm_pair(grid: Grid, ref: str, d_range: tuple[float, float]) -> F32:
    other = neighbour(grid, ref, 1, 0) or neighbour(grid, ref, -1, 0)
    if other is None:
        raise ValueError(f"camera {ref} has no horizontal neighbour")
    return pair_disparity(grid, ref, other, d_range)


def sgbm_wls(grid: Grid, ref: str, d_range: tuple[float, float], block: int = 5) -> F32:
    right = neighbour(grid, ref, 1, 0)
    flip = right is None
    other = right or neighbour(grid, ref, -1, 0)
    if other is None:
        raise ValueError(f"camera {ref} has no horizontal neighbour")
    scale = abs(grid.offsets[other][0] - grid.offsets[ref][0])
    a, b = _u8(grid.images[ref]), _u8(grid.images[other])
    if flip:
        a, b = np.ascontiguousarray(a[:, ::-1]), np.ascontiguousarray(b[:, ::-1])
    left_m = _sgbm(d_range[0] * scale, d_range[1] * scale, block)
    right_m = cv2.ximgproc.createRightMatcher(left_m)
    wls = cv2.ximgproc.createDisparityWLSFilter(left_m)
    wls.setLambda(8000.0)
    wls.setSigmaColor(1.5)
    dl = left_m.compute(a, b)
    dr = right_m.compute(b, a)
    out = wls.filter(dl, a, disparity_map_right=dr).astype(np.float32) / 16.0
    out[out < left_m.getMinDisparity()] = np.inf
    out = out[:, ::-1] if flip else out
    return np.ascontiguousarray(out / np.float32(scale), dtype=np.float32)


def sgbm_fused(grid: Grid, ref: str, d_range: tuple[float, float]) -> F32:
    """SGBM on every neighbouring pair, median of the estimates that exist."""
    maps = []
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        other = neighbour(grid, ref, dx, dy)
        if other is not None:
            maps.append(pair_disparity(grid, ref, other, d_range))
    stack = np.stack(maps)
    stack[~np.isfinite(stack)] = np.nan
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            fused = np.nanmedian(stack, axis=0)
    return np.asarray(np.where(np.isfinite(fused), fused, np.inf), dtype=np.float32)


BASELINES = {
    "opencv-sgbm-3way": sgbm_pair,
    "opencv-sgbm-wls": sgbm_wls,
    "opencv-sgbm-fused": sgbm_fused,
}
