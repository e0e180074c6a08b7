"""The plane-sweep engine (presets ``fast`` and ``balanced``): candidates are indexed by the disparity d of the
horizontal spacing, and camera b is sampled at (x - d (ox_b - ox_a), y - d (oy_b - oy_a)), so a vertical
neighbour moves by d * dy/dx. The planned range is swept at half resolution, one level at a time, with the cost
of ``cost.py``; ``balanced`` keeps every level in a (levels, h, w) volume of the searched box for semi-global
smoothing (``sgm.py``), so its memory grows with the range, while ``fast`` keeps only the best so far. With
refinement, a few candidates around the upsampled result are matched at full resolution and an equiangular (V)
fit through the best and its two neighbours gives the sub-pixel position, never more than half a step from the
best candidate."""

from __future__ import annotations

import math
import time

import cv2
import numpy as np

from rigctl.depth.cost import F32, INVALID_COST, TRUNCATE, SweepLevel, combine, side_groups
from rigctl.depth.search import BoxEstimate, SearchJob
from rigctl.depth.sgm import semi_global


def _odd(n: float) -> int:
    k = max(3, round(n))
    return k if k % 2 else k + 1


def sweep_engine(job: SearchJob) -> BoxEstimate:
    """Plane sweep over the planned range (half resolution from 64 px up), optionally smoothed semi-globally,
    then refined at full resolution around the upsampled result (or upsampled as it is)."""
    grid, ref, moving, box, keep, preset, stats = (
        job.grid,
        job.ref,
        job.moving,
        job.box,
        job.keep,
        job.preset,
        job.stats,
    )
    lo, hi = job.d_range
    h, w = grid.shape
    # coarse: stream over the planned range at half resolution
    t0 = time.perf_counter()
    scale = 0.5 if min(h, w) >= 64 else 1.0
    coarse = SweepLevel(grid, ref, moving, scale, box)
    win_c = _odd(preset.window * scale)
    levels = np.arange(math.floor(lo * scale) - 1, math.ceil(hi * scale) + 2, 1.0, dtype=np.float32)
    levels = levels[: max(1, min(len(levels), 4 * max(coarse.h, coarse.w)))]  # a range beyond the image is capped
    stats["levels"] = len(levels)
    groups_c = side_groups(coarse) if preset.keep == 0 else None
    best = np.full(coarse.ref.shape, np.inf, np.float32)
    best_d = np.zeros(coarse.ref.shape, np.float32)
    total = np.zeros(coarse.ref.shape, np.float32)
    volume = np.empty((len(levels), *coarse.ref.shape), np.float32) if preset.sgm else None
    for i, d in enumerate(levels):
        c = combine(coarse.cost_const(float(d), win_c), keep, groups_c)
        if volume is not None:
            volume[i] = c
            continue
        better = c < best
        best_d = np.where(better, d, best_d)
        best = np.minimum(best, c)
        total += np.minimum(c, TRUNCATE)
    if volume is not None and preset.sgm is not None:  # half resolution only: the full-resolution pass streams
        raw = np.minimum(volume, TRUNCATE)
        total = raw.sum(0)
        agg = semi_global(raw, preset.sgm[0], preset.sgm[1])
        k = np.argmin(agg, axis=0)
        best_d = levels[k].astype(np.float32)
        best = np.take_along_axis(raw, k[None], 0)[0]
        stats["sgm"] = True
    # distinctiveness: how far the best match stands below the average candidate
    second = total / len(levels)
    stats["coarse_s"] = time.perf_counter() - t0
    bound = (best_d <= levels[0] + 0.5) | (best_d >= levels[-1] - 0.5)
    no_view = best >= INVALID_COST * 0.5

    y0, y1, x0, x1 = box
    crop_h, crop_w = y1 - y0, x1 - x0
    t0 = time.perf_counter()
    if preset.refine and scale != 1.0:
        up = cv2.resize(best_d / scale, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
        D0: F32 = np.asarray(np.clip(up, lo, hi), dtype=np.float32)
        fine = SweepLevel(grid, ref, moving, 1.0, box)
        r = preset.radius
        groups_f = side_groups(fine) if preset.keep == 0 else None
        costs = np.stack(
            [combine(fine.cost_map(D0 + np.float32(k), preset.window), keep, groups_f) for k in range(-r, r + 1)]
        )
        if preset.sgm_fine:
            costs = semi_global(np.minimum(costs, TRUNCATE), preset.sgm_fine[0], preset.sgm_fine[1]) / np.float32(4)
        k_best = np.argmin(costs, axis=0)
        c0 = np.take_along_axis(costs, k_best[None], 0)[0]
        cm = np.take_along_axis(costs, np.clip(k_best - 1, 0, 2 * r)[None], 0)[0]
        cp = np.take_along_axis(costs, np.clip(k_best + 1, 0, 2 * r)[None], 0)[0]
        # equiangular (V) fit: the right model for an absolute-difference cost, with less pixel-locking bias
        # than a parabola
        rise = np.maximum(cm - c0, cp - c0)
        interior = (k_best > 0) & (k_best < 2 * r) & (rise > 1e-6)
        with np.errstate(divide="ignore", invalid="ignore"):
            sub = np.where(interior, 0.5 * (cm - cp) / rise, 0.0)
        sub = np.clip(sub, -0.5, 0.5)  # guarded: the V fit never moves the match by more than half a step
        disp = D0 + (k_best - r).astype(np.float32) + sub.astype(np.float32)
        cost = c0
        texture = fine.texture
        bright = fine.bright
    else:
        disp = cv2.resize(best_d / scale, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
        cost = cv2.resize(best, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
        texture = np.asarray(cv2.resize(coarse.texture, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR), np.float32)
        bright = np.asarray(cv2.resize(coarse.bright, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR), np.float32)
    # the coarse search's flags and distinctiveness, at the box's full resolution
    bound_full = cv2.resize(bound.astype(np.uint8), (crop_w, crop_h), interpolation=cv2.INTER_NEAREST).astype(bool)
    no_view_full = cv2.resize(no_view.astype(np.uint8), (crop_w, crop_h), interpolation=cv2.INTER_NEAREST).astype(bool)
    uniq = cv2.resize(second / np.maximum(best, 1e-6), (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
    stats["refine_s"] = time.perf_counter() - t0
    distinct = np.clip((np.nan_to_num(uniq, posinf=4.0) - 1.0) / 0.5, 0, 1).astype(np.float32)
    return BoxEstimate(
        np.asarray(disp, np.float32), np.asarray(cost, np.float32), distinct, texture, bright, bound_full, no_view_full
    )
