"""Semi-global aggregation of a cost volume (Hirschmueller's recursion) along four paths: left/right and
up/down. The plane sweep's ``balanced`` preset uses it at half resolution and over its refinement candidates."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]


def sgm_path(C: F32, p1: float, p2: float, reverse: bool) -> F32:
    """One semi-global path over axis 0 of C (steps, D, N): L = C + min(L', L'(d +- 1) + p1, min L' + p2) - min L'."""
    L = np.empty_like(C)
    order = range(C.shape[0] - 1, -1, -1) if reverse else range(C.shape[0])
    prev = None
    big = np.float32(1e9)
    for i in order:
        if prev is None:
            L[i] = C[i]
        else:
            m = prev.min(0)
            up = np.empty_like(prev)
            up[1:] = prev[:-1]
            up[0] = big
            down = np.empty_like(prev)
            down[:-1] = prev[1:]
            down[-1] = big
            best = np.minimum(np.minimum(prev, np.minimum(up, down) + p1), m + p2)
            L[i] = C[i] + best - m
        prev = L[i]
    return L


def semi_global(volume: F32, p1: float, p2: float) -> F32:
    """Four-path semi-global aggregation of a (D, H, W) cost volume (left/right, up/down)."""
    h_vol = np.ascontiguousarray(volume.transpose(2, 0, 1))  # (W, D, H)
    total = sgm_path(h_vol, p1, p2, False) + sgm_path(h_vol, p1, p2, True)
    out = np.ascontiguousarray(total.transpose(1, 2, 0))
    v_vol = np.ascontiguousarray(volume.transpose(1, 0, 2))  # (H, D, W)
    total_v = sgm_path(v_vol, p1, p2, False) + sgm_path(v_vol, p1, p2, True)
    out += total_v.transpose(1, 0, 2)
    return np.asarray(out, dtype=np.float32)
