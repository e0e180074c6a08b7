"""The ``best`` preset's engine as seen by ``estimate``: the sub-pixel cost volume (``costvolume.py``), the
continuous refinement along the baselines and the outlier clean-up (``refine.py``), on the keyed subject's box,
for every disparity range. The semi-global pairs are a second candidate chosen per pixel from the data
(``pick_pairs``). Only with fewer than three other views, where there is nothing to select occlusion-free
views from, does the ``pairs`` engine run alone. ``rigctl bench depth`` shows both on every dataset."""

from __future__ import annotations

import logging
import math
import time
from dataclasses import replace

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.coarse_to_fine import volume_disparity
from rigctl.depth.costvolume import F32, FRACTION, TRUNCATE, Aggregator, MatchViews, VolumeParams
from rigctl.depth.pair_fusion import pairs_engine
from rigctl.depth.pairs import neighbour
from rigctl.depth.presets import PRESETS
from rigctl.depth.refine import clean, refine
from rigctl.depth.search import BoxEstimate, SearchJob

log = logging.getLogger(__name__)
MIN_VIEWS = 3  # other views below which the pairs engine (semi-global) is the better start
CONFLICT_PX = 1.0  # the two candidates further apart than this disagree on the match, not on its sub-pixel part


def volume_engine(job: SearchJob) -> BoxEstimate:
    p, stats = job.preset, job.stats
    rel = {
        n: (
            job.grid.offsets[n][0] - job.grid.offsets[job.ref][0],
            job.grid.offsets[n][1] - job.grid.offsets[job.ref][1],
        )
        for n in job.moving
    }
    params = VolumeParams(job.keep, window=p.window, radius=p.guided_radius, eps=p.guided_eps)
    lo, hi = job.d_range
    if len(job.moving) < MIN_VIEWS and min(job.grid.shape) >= 16 and neighbour_count(job):
        stats["engine"] = f"pairs: only {len(job.moving)} other view(s)"
        pair_preset = PRESETS["pairs"]  # exactly the pairs preset's matching, window and views kept
        keep = max(1, math.ceil(pair_preset.keep * len(job.moving)))
        crop = pairs_engine(replace(job, preset=pair_preset, keep=keep))
        crop.disparity = np.asarray(cv2.medianBlur(np.ascontiguousarray(crop.disparity), 5), np.float32)
        return crop
    stats["engine"] = "cost volume"
    # the semi-global pairs first: their working set is gone before the views are made (issue 24: memory)
    t0 = time.perf_counter()
    with_pairs = bool(p.with_pairs and neighbour_count(job) and min(job.grid.shape) >= 16)
    pairs = pairs_engine(job).disparity if with_pairs else None
    t_pairs = time.perf_counter() - t0
    pair_levels = stats.get("levels")
    sw, views = volume_disparity(job.grid.images, job.ref, rel, job.box, job.d_range, params, stats, job.region)
    if pairs is not None and pair_levels is not None:
        stats["levels"] = pair_levels  # as reported before the pairs ran first: the widest pair's levels
    t0 = time.perf_counter() - t_pairs
    d = sw.disparity
    reach: float | F32 = FRACTION  # the refinement stays within the quarter-pixel cell the sweep chose
    if pairs is not None:
        # the semi-global pairs hold large weakly textured areas, steep slants and occlusion edges together;
        # where the views agree better with them, they win, and are refined in turn (from their 1/16 px)
        have = np.isfinite(pairs)
        picked = pick_pairs(views, d, np.where(have, pairs, d).astype(np.float32), params) & have
        d = np.where(picked, pairs, d).astype(np.float32)
        reach = np.where(picked, np.float32(0.5), np.float32(FRACTION)).astype(np.float32)
        stats["pairs_chosen_share"] = float(picked.mean())
        del pairs, have, picked
    t1 = time.perf_counter()
    stats["candidates_s"] = t1 - t0  # the semi-global pairs as a second candidate, and the choice between them
    if p.lk_iterations:
        d, _ = refine(views, d, job.keep, p.guided_radius, p.guided_eps, p.lk_iterations, reach=reach)
        stats["refine_pixel_levels"] = d.size * p.lk_iterations  # one disparity per pixel and step
    d, outliers = clean(np.clip(d, lo - 1.0, hi + 1.0).astype(np.float32))
    stats["refinement_s"] = time.perf_counter() - t1
    stats["outliers_replaced"] = int(outliers.sum())
    # the bands only some views see, at the frame's edges and behind every foreground edge (a nearer surface
    # of the estimate covers the point there): how many pixels rest on few views
    t2 = time.perf_counter()
    seen_by = views.visible_count(d, job.region, where=job.region)  # counted where it is reported
    stats["fewer_than_3_views_pixels"] = int((job.region & (seen_by < 3)).sum())
    stats["views_count_s"] = time.perf_counter() - t2
    stats["refine_s"] = time.perf_counter() - t0
    with np.errstate(divide="ignore", invalid="ignore"):
        uniq = np.where(sw.cost > 1e-6, sw.mean_cost / np.maximum(sw.cost, 1e-6), 4.0)
    distinct = np.clip((uniq - 1.0) / 0.5, 0, 1).astype(np.float32)
    cost = np.minimum(sw.cost, TRUNCATE).astype(np.float32)
    cost[sw.no_view] = sw.cost[sw.no_view]
    return BoxEstimate(d, cost, distinct, views.texture, views.bright, sw.bound, sw.no_view)


def pick_pairs(views: MatchViews, d: F32, pairs: F32, params: VolumeParams) -> NDArray[np.bool_]:
    """Where the semi-global pairs' estimate replaces the cost volume's. Within CONFLICT_PX of each other the
    aggregated cost decides (the sub-pixel part). Where they disagree on the match itself, that cost cannot
    referee: the cost volume's estimate is its minimum by construction, and its window assumes a
    fronto-parallel surface (a steep slant, a thin strip). There each view's difference at the pixel itself
    decides, over the best ``keep`` views that see it: a cost that neither candidate was fitted to."""
    conflict = np.abs(pairs - d) > CONFLICT_PX
    agg = Aggregator(views.guide, params.radius, params.eps)
    # the same aggregated cost as the sweep, each candidate's made and compared (issue 24: not stacked, no
    # argmin over the stack: 0.4 s a camera at 4K)
    first = agg(views.costs(d, params.window, params.keep))
    lower = second_lower(first, agg(views.costs(pairs, params.window, params.keep)))
    del first
    at_pixel = views.costs(pairs, 1, params.keep) < views.costs(d, 1, params.keep)
    return np.asarray(np.where(conflict, at_pixel, lower))


def neighbour_count(job: SearchJob) -> int:
    return sum(neighbour(job.grid, job.ref, dx, dy) is not None for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)))


def second_lower(first: F32, second: F32) -> NDArray[np.bool_]:
    """Per pixel, whether ``np.argmin(np.stack([first, second]), axis=0)`` is 1, without the stack: the second
    is lower, or it is NaN and the first is not (argmin takes the first NaN)."""
    return np.asarray((second < first) | (np.isnan(second) & ~np.isnan(first)))
