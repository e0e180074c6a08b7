"""How many views see each reference pixel's point at its disparity, as one compiled pass per view (the
``fewer_than_3_views_pixels`` of the report): the reference's own estimate splatted on each view as a
z-buffer, then each pixel counted unless everything around its place there is nearer. It computes what
``MatchViews.visible_count``'s numpy reference computes, the same counts (``tests/unit/test_cost_kernels.py``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # waiting threads sleep (see rigctl/render/kernels.py)

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@njit(parallel=True, cache=True, fastmath=False)
def _visible(
    d: F32,
    front: NDArray[np.bool_],
    rel: F32,
    y0: int,
    x0: int,
    tol: float,
    zbuf: F32,
    count: F32,
    where: NDArray[np.bool_],
    everywhere: bool,
) -> None:
    """Per view: every ``front`` pixel's disparity splatted (the largest kept) on the four cells around where
    the view sees it, then each pixel (``where``, unless ``everywhere``) counted as seen unless all four cells
    around its own place hold a disparity more than ``tol`` larger. The splat is serial (its cells are shared
    between rows), the count parallel over rows."""
    h, w = d.shape
    hh, ww = zbuf.shape
    t = np.float32(tol)
    zbuf[:] = -np.inf
    top, bottom, left, right = hh, 0, ww, 0  # the cells the last view's splat wrote (none yet)
    for v in range(rel.shape[0]):
        rx, ry = rel[v, 0], rel[v, 1]
        if top < bottom:  # only those are set back: the rest of the view never was written (issue 24)
            zbuf[top:bottom, left:right] = -np.inf
        top, bottom, left, right = hh, 0, ww, 0
        for y in range(h):
            for x in range(w):
                if not front[y, x]:
                    continue
                dd = d[y, x]
                mx, my = np.float32(x0 + x) - dd * rx, np.float32(y0 + y) - dd * ry
                if not (mx > -1.0 and mx < ww and my > -1.0 and my < hh):
                    continue
                xa, ya = int(np.floor(mx)), int(np.floor(my))
                top, bottom = min(top, max(ya, 0)), max(bottom, min(ya + 2, hh))
                left, right = min(left, max(xa, 0)), max(right, min(xa + 2, ww))
                for j in range(max(ya, 0), min(ya + 2, hh)):
                    for i in range(max(xa, 0), min(xa + 2, ww)):
                        if zbuf[j, i] < dd:
                            zbuf[j, i] = dd
        for y in prange(h):
            for x in range(w):
                if not (everywhere or where[y, x]):
                    continue
                dd = d[y, x]
                mx, my = np.float32(x0 + x) - dd * rx, np.float32(y0 + y) - dd * ry
                if not (mx >= 0.0 and mx <= ww - 1 and my >= 0.0 and my <= hh - 1):
                    continue
                xa, ya = int(np.floor(mx)), int(np.floor(my))
                nearest = np.float32(np.inf)
                for j in range(ya, min(ya + 2, hh)):
                    for i in range(xa, min(xa + 2, ww)):
                        nearest = min(nearest, zbuf[j, i])
                count[y, x] += np.float32(1.0) if not nearest > dd + t else np.float32(0.0)


def visible_views(
    d: F32,
    front: NDArray[np.bool_],
    rel: NDArray[np.float64],
    origin: tuple[int, int],
    size: tuple[int, int],
    tol: float,
    where: NDArray[np.bool_] | None = None,
) -> F32:
    """(h, w): how many views see the point of each reference pixel at its disparity ``d`` (h, w; the crop whose
    top-left pixel is ``origin`` (y, x) in views of ``size`` (H, W)): inside the view's frame and not hidden
    there by a ``front`` pixel of the reference whose disparity is more than ``tol`` larger (a nearer surface
    that lands on the same place). What ``MatchViews.visible_count``'s numpy reference computes; only at
    ``where`` when given (0 elsewhere)."""
    count = np.zeros(d.shape, np.float32)
    zbuf = np.empty(size, np.float32)
    _visible(
        np.ascontiguousarray(d, np.float32),
        np.ascontiguousarray(front, np.bool_),
        np.ascontiguousarray(rel, np.float32).reshape(-1, 2),
        origin[0],
        origin[1],
        tol,
        zbuf,
        count,
        np.ascontiguousarray(where if where is not None else np.zeros((1, 1), np.bool_), np.bool_),
        where is None,
    )
    return count


def visible_views_reference(
    d: F32,
    front: NDArray[np.bool_],
    rel: list[tuple[float, float]],
    grid: tuple[F32, F32],
    size: tuple[int, int],
    tol: float,
) -> NDArray[np.int32]:
    """:func:`visible_views` in numpy (``MatchViews.visible_count`` with ``COMPILED`` off), everywhere:
    ``grid`` (gy, gx) the crop's rows and columns in views of ``size`` (h, w), ``rel`` the baselines."""
    h, w = size
    gy, gx = grid
    n = np.zeros(d.shape, np.int32)
    for rx, ry in rel:
        mx, my = gx - d * np.float32(rx), gy - d * np.float32(ry)
        inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
        zbuf = np.full((h, w), -np.inf, np.float32)
        sx, sy = mx[front], my[front]
        reach = (sx > -1) & (sx < w) & (sy > -1) & (sy < h)
        sx, sy, sd = sx[reach], sy[reach], d[front][reach]
        xa, ya = np.floor(sx).astype(np.int64), np.floor(sy).astype(np.int64)
        for j in (ya, ya + 1):
            for i in (xa, xa + 1):
                ok = (j >= 0) & (j < h) & (i >= 0) & (i < w)
                np.maximum.at(zbuf, (j[ok], i[ok]), sd[ok])
        xa = np.clip(np.floor(mx).astype(np.int64), 0, w - 1)
        ya = np.clip(np.floor(my).astype(np.int64), 0, h - 1)
        xb, yb = np.minimum(xa + 1, w - 1), np.minimum(ya + 1, h - 1)
        nearest = np.minimum(np.minimum(zbuf[ya, xa], zbuf[ya, xb]), np.minimum(zbuf[yb, xa], zbuf[yb, xb]))
        n += inside & ~(nearest > d + np.float32(tol))
    return n
