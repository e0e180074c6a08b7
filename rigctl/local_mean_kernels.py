"""The soft key's wide local means compiled (Numba): a frame's values times a weight, shrunk by whole blocks
in one pass (:meth:`rigctl.local_mean.LocalMean.shrunk`). The numpy and OpenCV path multiplies the frame in
bands and hands each to OpenCV's area resize, which reads it back: a pass and a frame-sized write per wide
blur, three to five a camera (issue 24: the soft key was the write's critical path). This kernel sums each
block's products in OpenCV's order (its integer-scale area resize, in float32: row by row, four at a time) and
scales the sum as it does, so the values are the same bit for bit (``tests/unit/test_local_mean.py``; a NaN
may differ in its sign bit). Not parallel: the soft key runs it in its own thread beside the EXR writer's
compiled passes, and only numba's TBB and OpenMP layers take parallel calls from two threads at once."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False)
def shrunk_product(  # pragma: no cover  (compiled)
    values: np.ndarray, weight: np.ndarray, scale: int, out: np.ndarray, rows: tuple, columns: tuple
) -> None:
    """``out`` (H/scale x W/scale x C) at ``rows`` and ``columns`` (first, end): the mean of ``values`` (H x W
    x C, float32) times ``weight`` (H x W, uint8 or float32, the product float32) over each ``scale`` x
    ``scale`` block, summed as OpenCV's area resize sums it: the block's k-th product row-major, each group of four
    added up first and then to the sum, the rest (past the last whole group) one by one, and the sum times
    1 / scale**2 in float32. The rest of ``out`` is left as it is."""
    c = out.shape[2]
    area = scale * scale
    inv = np.float32(1.0) / np.float32(area)
    whole = area - area % 4
    for by in range(rows[0], rows[1]):
        total = np.zeros(c, np.float32)
        group = np.zeros(c, np.float32)
        for bx in range(columns[0], columns[1]):
            total[:] = 0.0
            k = 0
            for y in range(by * scale, by * scale + scale):
                for x in range(bx * scale, bx * scale + scale):
                    wt = np.float32(weight[y, x])
                    if k >= whole:
                        for ch in range(c):
                            total[ch] += values[y, x, ch] * wt
                    elif k % 4 == 0:
                        for ch in range(c):
                            group[ch] = values[y, x, ch] * wt
                    else:
                        for ch in range(c):
                            group[ch] += values[y, x, ch] * wt
                        if k % 4 == 3:
                            for ch in range(c):
                                total[ch] += group[ch]
                    k += 1
            for ch in range(c):
                out[by, bx, ch] = total[ch] * inv
