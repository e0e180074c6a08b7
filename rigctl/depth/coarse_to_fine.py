"""The cost volume's sweeps from coarse to fine (the ``best`` preset's engine, ``costvolume.py``): the integer
sweep over the planned range at the scale that range needs (``coarse_scale``), at quarter scale then a band at
half scale (``band``), then the fractional sweep at full resolution around the result (``volume_disparity``).
The switches and steps live in ``costvolume`` (read at each call, so a test can change them there)."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping

import cv2
import numpy as np
from numpy.typing import NDArray

import rigctl.depth.costvolume as cvol
from rigctl.depth.cost import active_pixels
from rigctl.depth.cost_kernels import computed_pixels
from rigctl.depth.costvolume import F32, Around, MatchViews, Sweep, VolumeParams, sweep
from rigctl.depth.search import EstimateStats


def coarse_scale(levels: float, size: tuple[int, int]) -> float:
    """Scale of the integer sweep: full resolution up to MAX_LEVELS levels, halved until the range fits
    (never below a quarter, nor below 32 px of image)."""
    s = 1.0
    while levels * s > cvol.MAX_LEVELS and s > 0.25 and min(size) * s >= 64:
        s /= 2
    return s


def volume_disparity(
    images: Mapping[str, F32],
    ref: str,
    rel: dict[str, tuple[float, float]],
    box: tuple[int, int, int, int],
    d_range: tuple[float, float],
    p: VolumeParams,
    stats: EstimateStats,
    region: NDArray[np.bool_] | None = None,
) -> tuple[Sweep, MatchViews]:
    """Integer then fractional sweep for the reference crop ``box``; returns the fractional result and the
    full-resolution views (for the continuous refinement). ``region`` (box-sized): the pixels estimated; the
    costs are computed within CONTEXT_PX of them (``active``), no cost elsewhere (the keyed background's)."""
    lo, hi = d_range
    y0, y1, x0, x1 = box
    t0 = time.perf_counter()
    s = coarse_scale(hi - lo + 1, (y1 - y0, x1 - x0))
    centre = 0.5 * (lo + hi)
    pad = reach_pad(rel)
    asked = (lo - pad, hi + pad)  # every disparity the views are asked for (REACH_PAD)
    cv = MatchViews(images, ref, rel, box, s, centre, asked)
    grow = cvol.CONTEXT_PX + 4 * p.radius + 2 * p.window  # what the filters around an estimate read
    cv.active = active_pixels(region, s, cv.shape, grow)
    first, last = math.floor(lo * s) - 1, math.ceil(hi * s) + 1
    levels = [float(v) for v in np.arange(first, last + 1, 1.0)]
    levels = levels[: max(1, 4 * max(cv.h, cv.w))]  # a range far beyond the image is capped
    stats["levels"] = len(levels)
    stats["coarse_scale"] = s
    stats["integer_sweep_pixel_levels"] = computed_pixels(cv.active, cv.shape, p.window) * len(levels)
    coarse = sweep(cv, list(levels), p, p.window, max(1, round(p.radius * s)), stats)
    stats["integer_sweep_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if s != 1.0:
        del cv  # the coarse views go before the full-resolution ones are made
    d0 = coarse.disparity / np.float32(s)
    banded = cvol.BAND and s < cvol.BAND_SCALE
    if banded:
        d0 = band(images, ref, rel, box, (lo, hi), (centre, asked), d0, region, grow, p, stats)
        t0 = time.perf_counter()  # fractional_sweep_s without the band's own (band_sweep_s)
    act = active_pixels(region, 1.0, None, grow)
    full = cv if s == 1.0 else MatchViews(images, ref, rel, box, 1.0, centre, asked, act)
    h, w = full.shape
    if s != 1.0:
        d0 = np.asarray(cv2.resize(d0, (w, h), interpolation=cv2.INTER_NEAREST), np.float32)
    d0 = np.clip(d0, lo, hi).astype(np.float32)
    if banded:  # +-1 px by half pixels: the parabola, then the refinement, make the sub-pixel part
        reach, step = cvol.BAND_REACH, cvol.WIDE_STEP
    else:
        reach = max(1.0, 0.75 / s)  # how far the truth may lie from the coarse result, full-resolution px
        step = cvol.FRACTION if s >= 0.5 else cvol.WIDE_STEP
    n_side = math.ceil(reach / step)
    cands = Around(d0, step, n_side)
    stats["fractional_sweep_pixel_levels"] = computed_pixels(full.active, full.shape, p.window) * len(cands)
    fine = sweep(full, cands, p, p.window, p.radius, stats)
    stats["fractional_candidates"] = len(cands)
    stats["fractional_step"] = step
    stats["fractional_sweep_s"] = time.perf_counter() - t0
    bound = coarse.bound
    if s != 1.0:
        bound = np.asarray(cv2.resize(bound.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST)) > 0
    fine.bound = np.asarray(bound) & ((fine.disparity <= lo + 0.5) | (fine.disparity >= hi - 0.5))
    fine.mean_cost = np.asarray(
        coarse.mean_cost if s == 1.0 else cv2.resize(coarse.mean_cost, (w, h), interpolation=cv2.INTER_LINEAR),
        np.float32,
    )
    fine.disparity = np.clip(fine.disparity, lo - 1.0, hi + 1.0).astype(np.float32)
    return fine, full


def band(
    images: Mapping[str, F32],
    ref: str,
    rel: dict[str, tuple[float, float]],
    box: tuple[int, int, int, int],
    d_range: tuple[float, float],
    where: tuple[float, tuple[float, float]],
    d0: F32,
    region: NDArray[np.bool_] | None,
    grow: int,
    p: VolumeParams,
    stats: EstimateStats,
) -> F32:
    """The sweep between a quarter-scale integer sweep and the full resolution (coarse to fine): at half scale,
    +-3 full-resolution px around the coarse result ``d0`` (full-resolution px, at the coarse scale) by whole
    pixels (BAND_CANDIDATES: a quarter of the pixels each), so that the full-resolution sweep needs only
    +-1 px. Returns the result in full-resolution px, at half scale."""
    lo, hi = d_range
    t0 = time.perf_counter()
    centre, asked = where
    mid = MatchViews(images, ref, rel, box, cvol.BAND_SCALE, centre, asked)
    mid.active = active_pixels(region, cvol.BAND_SCALE, mid.shape, grow)
    hh, hw = mid.shape
    start = np.asarray(
        cv2.resize(d0 * np.float32(cvol.BAND_SCALE), (hw, hh), interpolation=cv2.INTER_NEAREST), np.float32
    )
    start = np.clip(start, lo * cvol.BAND_SCALE, hi * cvol.BAND_SCALE).astype(np.float32)
    side = cvol.BAND_CANDIDATES // 2
    cands = Around(start, 1.0 * cvol.BAND_SCALE, side)  # one full-resolution px apart
    stats["band_sweep_pixel_levels"] = computed_pixels(mid.active, mid.shape, p.window) * len(cands)
    res = sweep(mid, cands, p, p.window, max(1, round(p.radius * cvol.BAND_SCALE)), stats)
    stats["band_scale"] = cvol.BAND_SCALE
    stats["band_sweep_s"] = time.perf_counter() - t0
    out = (res.disparity / np.float32(cvol.BAND_SCALE)).astype(np.float32)
    if cvol.BAND_MEDIAN:
        out = np.asarray(cv2.medianBlur(out, cvol.BAND_MEDIAN), np.float32)
    return out


def reach_pad(rel: dict[str, tuple[float, float]]) -> float:
    """REACH_PAD, or more where a semi-global pair's 16 extra levels (its own px) reach further: a pair whose
    baseline is shorter than half the horizontal spacing."""
    steps = [abs(v) for r in rel.values() for v in r if abs(v) > 1e-6]
    return max(cvol.REACH_PAD, 17.0 / min(steps) + 2.0) if steps else cvol.REACH_PAD
