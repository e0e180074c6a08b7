"""One Gauss-Newton step's normal equations of the continuous refinement (``refine.refine``) as compiled
passes (Numba): per view and pixel the residual at the current disparity and its derivative along the
baseline, then per pixel the sums over the views that fit best locally. What the reference path computes
with ``cv2.remap``, ``cv2.boxFilter`` and ``np.partition`` (``tests/unit/test_cost_kernels.py`` asserts the two
agree). The bilinear sample and the vertical box sums are the cost kernels' (``cost_kernels.py``), so the
refinement reads the views exactly as the sweep did."""

from __future__ import annotations

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from rigctl.depth import cost_kernels
from rigctl.depth.cost_kernels import reflect101, sample3, vertical_sum

F32 = NDArray[np.float32]


@njit(parallel=True, cache=True, fastmath=False)
def _residuals(
    levels: F32,
    ref: F32,
    rel: F32,
    d: F32,
    y0: int,
    x0: int,
    inv: float,
    tau_i: float,
    res: F32,
    jac: F32,
    tr: F32,
    org: NDArray[np.int64],
    fh: int,
    fw: int,
) -> None:
    """Per view and pixel: the intensity residual at disparity ``d`` (INVALID outside the view's frame,
    ``fh`` x ``fw``), its derivative along the baseline (0 outside) and the residual truncated at ``tau_i``.
    ``levels[v]``: the part of view v whose top-left pixel is ``org[v]`` (y, x), with one pixel around it
    (``feature_kernels.view_levels``)."""
    nv, hh, ww = levels.shape[0], levels.shape[1] - 2, levels.shape[2] - 2
    h, w = d.shape
    big, ti = np.float32(inv), np.float32(tau_i)
    for y in prange(h):
        gy = np.float32(y0 + y)
        for v in range(nv):
            rx, ry = rel[v, 0], rel[v, 1]
            oy, ox = org[v, 0], org[v, 1]
            for x in range(w):
                mx = np.float32(x0 + x) - d[y, x] * rx
                my = gy - d[y, x] * ry
                if (mx < 0) | (mx > fw - 1) | (my < 0) | (my > fh - 1):
                    res[v, y, x], jac[v, y, x], tr[v, y, x] = big, np.float32(0.0), ti
                    continue
                bx, by = np.floor(mx), np.floor(my)
                ex, ey = mx - bx, my - by
                ix, iy = int(bx) - ox, int(by) - oy
                xa, xb = min(max(ix, 0), ww - 1), min(max(ix + 1, 0), ww - 1)
                ya, yb = min(max(iy, 0), hh - 1), min(max(iy + 1, 0), hh - 1)
                w00 = (np.float32(1.0) - ey) * (np.float32(1.0) - ex)
                w01 = (np.float32(1.0) - ey) * ex
                w10 = ey * (np.float32(1.0) - ex)
                w11 = ey * ex
                s0, s1, s2 = sample3(levels, v, ya, yb, xa, xb, w00, w01, w10, w11)
                r = s0 - ref[y, x, 0]
                res[v, y, x] = r
                jac[v, y, x] = -(rx * s1 + ry * s2)
                tr[v, y, x] = min(abs(r), ti)


@njit(parallel=True, cache=True, fastmath=False)
def _selected_sums(
    res: F32,
    jac: F32,
    tr: F32,
    keep: int,
    inv: float,
    tau_i: float,
    a_out: F32,
    b_out: F32,
    first: int,
    h: int,
    a0: int,
) -> None:
    """Per pixel: each view's 5x5 mean truncated residual (its local fit), the ``keep`` views with the
    smallest (all views tied at the cut: a view is used where fewer than ``keep`` fit strictly better), and
    over them sum(J^2) / keep and sum(J r) / keep, r clipped. Row by row, each loop over the row's pixels.
    ``a_out``, ``b_out``: rows ``first`` on of h; ``res``, ``jac``, ``tr`` rows ``a0`` on (the 5x5's included)."""
    nv, w = res.shape[0], res.shape[2]
    half = np.float32(inv * 0.5)
    clip = np.float32(4 * tau_i)
    k = min(keep, nv)
    for yo in prange(a_out.shape[0]):
        y = first + yo
        cols = np.empty((nv, w), np.float64)
        loc = np.empty((nv, w), np.float32)
        rank = np.empty(w, np.int32)
        a = np.zeros(w, np.float32)
        b = np.zeros(w, np.float32)
        for v in range(nv):
            cv = cols[v]
            vertical_sum(cv, tr, v, y, 2, True, h, a0)
            lv = loc[v]
            for x in range(w):
                acc = 0.0
                for dx in range(-2, 3):
                    acc += cv[reflect101(x + dx, w)]
                lv[x] = np.float32(acc / 25.0)
            for x in range(w):
                if abs(res[v, y - a0, x]) >= half:
                    lv[x] = np.float32(inv)
        for i in range(nv):
            li = loc[i]
            rank[:] = 0
            for j in range(nv):
                lj = loc[j]
                for x in range(w):
                    rank[x] += lj[x] < li[x]
            for x in range(w):
                use = (rank[x] < k) & (li[x] < half)
                jv = jac[i, y - a0, x] if use else np.float32(0.0)
                rv = min(max(res[i, y - a0, x], -clip), clip) if use else np.float32(0.0)
                a[x] += jv * jv
                b[x] += jv * rv
        for x in range(w):
            a_out[yo, x] = a[x] / np.float32(k)
            b_out[yo, x] = b[x] / np.float32(k)


def refine_sums(
    levels: F32,
    ref: F32,
    rel: NDArray[np.float64],
    d: F32,
    origin: tuple[int, int],
    keep: int,
    inv: float,
    tau_i: float,
    org: NDArray[np.int64] | None = None,
    frame: tuple[int, int] | None = None,
    active: NDArray[np.bool_] | None = None,
) -> tuple[F32, F32]:
    """One Gauss-Newton step's normal equations before their aggregation (``refine.refine``): per pixel the
    sums of J^2 and J r over the ``keep`` views that fit best locally, divided by ``keep``. What the
    reference path computes with ``cv2.remap``, ``cv2.boxFilter`` and ``np.partition`` over the views.
    ``org``, ``frame``, ``active``: as for :func:`combined_costs` (beside the active columns, sums 0: no step)."""
    nv = levels.shape[0]
    fh, fw = frame if frame is not None else (levels.shape[1] - 2, levels.shape[2] - 2)
    org = np.zeros((nv, 2), np.int64) if org is None else np.ascontiguousarray(org, np.int64)
    h, w = d.shape
    dm = np.ascontiguousarray(d, np.float32)
    rel32 = rel.astype(np.float32)
    a_sum = np.empty((h, w), np.float32)
    b_sum = np.empty((h, w), np.float32)
    for a in range(0, h, cost_kernels.ROWS):  # in blocks of rows with the 5x5's rows around them, as combined_costs
        b = min(h, a + cost_kernels.ROWS)
        a0, b0 = max(0, a - 2), min(h, b + 2)
        ca, cb = (0, w) if active is None else cost_kernels.block_columns(active, a, b, 2)
        a_sum[a:b, :ca] = a_sum[a:b, cb:] = b_sum[a:b, :ca] = b_sum[a:b, cb:] = 0.0
        if cb <= ca:
            continue
        res = np.empty((nv, b0 - a0, cb - ca), np.float32)
        jac = np.empty((nv, b0 - a0, cb - ca), np.float32)
        tr = np.empty((nv, b0 - a0, cb - ca), np.float32)
        y0, x0 = origin
        ref_b, d_b = np.ascontiguousarray(ref[a0:b0, ca:cb]), np.ascontiguousarray(dm[a0:b0, ca:cb])
        _residuals(levels, ref_b, rel32, d_b, y0 + a0, x0 + ca, inv, tau_i, res, jac, tr, org, fh, fw)
        if ca == 0 and cb == w:
            _selected_sums(res, jac, tr, keep, inv, tau_i, a_sum[a:b], b_sum[a:b], a, h, a0)
        else:
            a_part, b_part = np.empty((b - a, cb - ca), np.float32), np.empty((b - a, cb - ca), np.float32)
            _selected_sums(res, jac, tr, keep, inv, tau_i, a_part, b_part, a, h, a0)
            a_sum[a:b, ca:cb], b_sum[a:b, ca:cb] = a_part, b_part
    return a_sum, b_sum
