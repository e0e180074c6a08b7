"""OpenCV baselines for ``rigctl bench depth``, measured on the same grids and disparity ranges as our presets:
SGBM 3WAY on the horizontal pair, SGBM with the WLS filter, and SGBM run on every neighbouring pair (left,
right, above, below: flipped and transposed so each is a left-right pair) and fused by the median."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import Grid
from rigctl.depth.pairs import F32, make_sgbm, nan_median, neighbour, pair_disparity
from rigctl.errors import ParameterError


def sgbm_pair(grid: Grid, ref: str, d_range: tuple[float, float]) -> F32:
    other = neighbour(grid, ref, 1, 0) or neighbour(grid, ref, -1, 0)
    if other is None:
        raise ParameterError(f"camera {ref} has no horizontal neighbour")
    return pair_disparity(grid, ref, other, d_range)


def sgbm_wls(grid: Grid, ref: str, d_range: tuple[float, float], block: int = 5) -> F32:
    right = neighbour(grid, ref, 1, 0)
    flip = right is None
    other = right or neighbour(grid, ref, -1, 0)
    if other is None:
        raise ParameterError(f"camera {ref} has no horizontal neighbour")
    scale = abs(grid.offsets[other][0] - grid.offsets[ref][0])
    a, b = grid.bgr8(ref), grid.bgr8(other)
    if flip:
        a, b = np.ascontiguousarray(a[:, ::-1]), np.ascontiguousarray(b[:, ::-1])
    left_m = make_sgbm(d_range[0] * scale, d_range[1] * scale, block)
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
    u8: dict[str, NDArray[np.uint8]] = {}
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        other = neighbour(grid, ref, dx, dy)
        if other is not None:
            maps.append(pair_disparity(grid, ref, other, d_range, u8=u8))
    fused, _ = nan_median(np.stack(maps))  # what no pair estimated (+-inf or NaN) is ignored
    return np.asarray(np.where(np.isfinite(fused), fused, np.inf), dtype=np.float32)


BASELINES = {
    "opencv-sgbm-3way": sgbm_pair,
    "opencv-sgbm-wls": sgbm_wls,
    "opencv-sgbm-fused": sgbm_fused,
}
