"""Continuous refinement of a disparity map along the baselines, and an outlier clean-up that keeps sub-pixel
values.

Multi-view photometric least squares (Lucas-Kanade along each view's epipolar direction): for every view v
kept at the pixel, the residual r_v = N_v(x - d r_v) - N_ref(x) and its derivative g_v = dr_v/dd are summed
over an edge-aware window (the guided filter), and d moves by -sum(g r) / sum(g g). The update has no
preferred fractional value, so the result does not lock to the sweep's sampling grid. A step is bounded, and
a pixel whose baseline gradient is too weak to carry a fit keeps the sweep's value.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.cost import INVALID_COST
from rigctl.depth.costvolume import TAU_I, Aggregator, MatchViews
from rigctl.depth.refine_kernels import refine_sums

F32 = NDArray[np.float32]
log = logging.getLogger(__name__)

COMPILED = True  # each step's sums by the compiled kernel (refine_kernels.refine_sums); False: OpenCV and numpy
DAMPING = 2e-5  # squared baseline gradient (grey 0..1 per px) at which a fit is trusted half: about sensor noise


def refine(
    views: MatchViews,
    disp: F32,
    keep: int,
    radius: int,
    eps: float,
    iterations: int = 3,
    reach: float | F32 = 1.0,
) -> tuple[F32, F32]:
    """Gauss-Newton along the baselines, over the ``keep`` views with the smallest residual at each pixel.
    Returns the refined map (within ``reach`` px of ``disp``, a number or a map) and the fit's strength (sum of g^2)."""
    agg = Aggregator(views.guide, radius, eps)
    disp = np.asarray(disp, np.float32)
    d = disp.copy()
    strength = np.zeros_like(d)
    lo, hi = disp - reach, disp + reach  # the same planes each step
    nv = len(views.names)
    for _ in range(iterations):
        if COMPILED and nv:
            y0, _, x0, _ = views.box
            a_raw, b_raw = refine_sums(
                views.levels,
                views.ref,
                views.rel_array,
                d,
                (y0, x0),
                keep,
                INVALID_COST,
                TAU_I,
                views.org,
                (views.h, views.w),
                views.active,
            )
            a = agg.smooth(a_raw)
            del a_raw  # each sum goes once filtered (issue 24: the 4K estimate's peak is here)
            b = agg.smooth(b_raw)
            del b_raw
        else:
            a, b = _normal_equations(views, d, keep, agg)
        # damped (Levenberg): where the baseline gradient is weaker than the noise, the pixel barely moves.
        # -b / (a + DAMPING), clipped to a quarter pixel, added to d, held within reach of the start: the same
        # ufuncs in the same order, in place in b's plane (no frame-sized temporaries beside the filter's)
        step = np.negative(b, out=b)
        np.divide(step, a + np.float32(DAMPING), out=step)
        np.clip(step, -0.25, 0.25, out=step)
        np.add(d, step, out=step)
        d = np.clip(step, lo, hi, out=step)
        strength = a
    return d, strength


def _normal_equations(views: MatchViews, d: F32, keep: int, agg: Aggregator) -> tuple[F32, F32]:
    """The reference path of one step (OpenCV and numpy): the aggregated sums of J^2 and J r over the best
    ``keep`` views, divided by ``keep``; ``refine_kernels.refine_sums`` computes the sums compiled."""
    nv = len(views.names)
    res = np.empty((nv, *d.shape), np.float32)
    jac = np.empty((nv, *d.shape), np.float32)
    for i, n in enumerate(views.names):
        rx, ry = views.rel[n]
        warped, outside = views.warp(n, d)  # intensity, d/dx, d/dy at the warped points
        res[i] = np.where(outside, np.float32(INVALID_COST), warped[..., 0] - views.ref[..., 0])
        jac[i] = np.where(outside, 0.0, -(rx * warped[..., 1] + ry * warped[..., 2]))
    # view selection: the views whose local residual is smallest (an occluded view has a large one)
    local = np.stack([cv2.boxFilter(np.minimum(np.abs(r), TAU_I), -1, (5, 5)) for r in res])
    local[np.abs(res) >= INVALID_COST * 0.5] = INVALID_COST
    k = min(keep, nv)
    cut = np.partition(local, k - 1, axis=0)[k - 1] if k < nv else np.full(d.shape, np.inf, np.float32)
    use = (local <= cut[None]) & (local < INVALID_COST * 0.5)
    r_c = np.clip(np.where(use, res, 0.0), -4 * TAU_I, 4 * TAU_I)
    j_u = np.where(use, jac, 0.0)
    a = agg.smooth((j_u * j_u).sum(0) / np.float32(k))
    b = agg.smooth((j_u * r_c).sum(0) / np.float32(k))
    return a, b


def clean(disp: F32, tol: float = 1.0) -> tuple[F32, NDArray[np.bool_]]:
    """Pixels further than ``tol`` from their 5x5 median take the median; every other pixel keeps its own
    sub-pixel value (a median filter over the whole map would round slopes to its neighbours' values)."""
    med = np.asarray(cv2.medianBlur(np.ascontiguousarray(disp, np.float32), 5), np.float32)
    out_of_line = np.abs(disp - med) > tol
    return np.where(out_of_line, med, disp).astype(np.float32), np.asarray(out_of_line)
