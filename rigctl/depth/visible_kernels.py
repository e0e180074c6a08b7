"""How many views see each reference pixel's point at its disparity, as one compiled pass per view (the
``fewer_than_3_views_pixels`` of the report): the reference's own estimate splatted on each view as a
z-buffer (in bands of the view's rows at once), then each pixel counted unless everything around its place
there is nearer. It computes what ``MatchViews.visible_count``'s numpy reference computes, the same counts
(``tests/unit/test_cost_kernels.py``, for any number of bands).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # waiting threads sleep (see rigctl/render/kernels.py)

import numba
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
    bands: int,
) -> None:
    """Per view: every ``front`` pixel's disparity splatted (the largest kept) on the four cells around where
    the view sees it, then each pixel (``where``, unless ``everywhere``) counted as seen unless all four cells
    around its own place hold a disparity more than ``tol`` larger. The splat runs in ``bands`` of the view's
    rows at once, each band writing only its own rows from the reference rows that can land there (the
    largest of a cell's disparities is the same in any order: the same z-buffer), the count over rows."""
    h, w = d.shape
    hh, ww = zbuf.shape
    t = np.float32(tol)
    zbuf[:] = -np.inf
    lo, hi = np.inf, -np.inf  # the front's finite disparities: which reference rows reach a band
    for y in range(h):
        for x in range(w):
            if front[y, x] and np.isfinite(d[y, x]):
                lo, hi = min(lo, float(d[y, x])), max(hi, float(d[y, x]))
    nb = max(1, min(bands, hh))
    written = np.empty((nb, 4), np.int64)  # per band, the cells the last view's splat wrote (none yet)
    for k in range(nb):
        written[k, 0], written[k, 1], written[k, 2], written[k, 3] = hh, 0, ww, 0
    for v in range(rel.shape[0]):
        rx, ry = rel[v, 0], rel[v, 1]
        for k in prange(nb):
            a, b = k * hh // nb, (k + 1) * hh // nb
            top, bottom, left, right = written[k, 0], written[k, 1], written[k, 2], written[k, 3]
            if top < bottom:  # only those are set back: the rest of the view never was written (issue 24)
                zbuf[top:bottom, left:right] = -np.inf
            top, bottom, left, right = hh, 0, ww, 0
            if lo <= hi:
                # a pixel of row y lands on view row y0 + y - d ry, its cells on that row's floor and the next
                s_lo, s_hi = min(lo * ry, hi * ry), max(lo * ry, hi * ry)
                first = max(0, int(np.floor(a - 1 - y0 + s_lo)) - 2)
                last = min(h, int(np.ceil(b - y0 + s_hi)) + 2)
                for y in range(first, last):
                    for x in range(w):
                        if not front[y, x]:
                            continue
                        dd = d[y, x]
                        mx, my = np.float32(x0 + x) - dd * rx, np.float32(y0 + y) - dd * ry
                        if not (mx > -1.0 and mx < ww and my > -1.0 and my < hh):
                            continue
                        xa, ya = int(np.floor(mx)), int(np.floor(my))
                        j0, j1 = max(ya, a), min(ya + 2, b)
                        if j0 >= j1:
                            continue
                        i0, i1 = max(xa, 0), min(xa + 2, ww)
                        top, bottom = min(top, j0), max(bottom, j1)
                        left, right = min(left, i0), max(right, i1)
                        for j in range(j0, j1):
                            for i in range(i0, i1):
                                if zbuf[j, i] < dd:
                                    zbuf[j, i] = dd
            written[k, 0], written[k, 1], written[k, 2], written[k, 3] = top, bottom, left, right
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
    bands: int | None = None,
) -> F32:
    """(h, w): how many views see the point of each reference pixel at its disparity ``d`` (h, w; the crop whose
    top-left pixel is ``origin`` (y, x) in views of ``size`` (H, W)): inside the view's frame and not hidden
    there by a ``front`` pixel of the reference whose disparity is more than ``tol`` larger (a nearer surface
    that lands on the same place). What ``MatchViews.visible_count``'s numpy reference computes; only at
    ``where`` when given (0 elsewhere). ``bands``: the splat's bands of rows (default: one per thread)."""
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
        numba.get_num_threads() if bands is None else bands,
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
