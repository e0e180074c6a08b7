"""The ``best`` preset's engine as seen by ``estimate``: the sub-pixel cost volume (``costvolume.py``), the
continuous refinement along the baselines and the outlier clean-up (``refine.py``), on the keyed subject's box.
Chosen per input: with fewer than three other views there is nothing to select occlusion-free views from,
and with disparities beyond WIDE_PX the semi-global pairs hold wide occlusion bands together; both use the
``pairs`` engine (today's results there, unchanged). ``rigctl bench depth`` shows both engines on every dataset."""

from __future__ import annotations

import logging
import math
import time
from dataclasses import replace

import cv2
import numpy as np

from rigctl.depth.costvolume import FRACTION, TRUNCATE, VolumeParams, choose, volume_disparity
from rigctl.depth.pair_fusion import pairs_engine
from rigctl.depth.pairs import neighbour
from rigctl.depth.presets import PRESETS
from rigctl.depth.refine import clean, refine
from rigctl.depth.search import BoxEstimate, SearchJob

log = logging.getLogger(__name__)
MIN_VIEWS = 3  # other views below which the pairs engine (semi-global) is the better start
# disparity magnitude (px of one spacing) above which the pairs engine is used: wide disparities open wide
# half-occluded bands and large weakly textured areas that semi-global smoothing holds together (the realistic
# presenter, 85-128 px), while narrow ones (light fields, a few px) need the cost volume's sub-pixel accuracy
WIDE_PX = 48.0


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
    few = len(job.moving) < MIN_VIEWS
    wide = max(abs(lo), abs(hi)) > WIDE_PX
    if (few or wide) and min(job.grid.shape) >= 16 and neighbour_count(job):
        stats["engine"] = "pairs: " + (f"only {len(job.moving)} other view(s)" if few else f"range beyond {WIDE_PX} px")
        pair_preset = PRESETS["pairs"]  # exactly the pairs preset's matching, window and views kept
        keep = max(1, math.ceil(pair_preset.keep * len(job.moving)))
        crop = pairs_engine(replace(job, preset=pair_preset, keep=keep))
        crop.disparity = np.asarray(cv2.medianBlur(np.ascontiguousarray(crop.disparity), 5), np.float32)
        return crop
    stats["engine"] = "cost volume"
    sw, views = volume_disparity(dict(job.grid.images), job.ref, rel, job.box, job.d_range, params, stats)
    t0 = time.perf_counter()
    d = sw.disparity
    if p.lk_iterations:
        d, _ = refine(views, d, job.keep, p.guided_radius, p.guided_eps, p.lk_iterations, reach=FRACTION)
    if p.with_pairs and neighbour_count(job) and min(job.grid.shape) >= 16:
        # the semi-global pairs hold large weakly textured areas and occlusion edges together; where the views
        # agree better with them, they win, and are refined in turn
        pairs = pairs_engine(job).disparity
        have = np.isfinite(pairs)
        cand = np.where(have, pairs, d).astype(np.float32)
        k = choose(views, [d, cand], params)
        picked = (k == 1) & have
        if p.lk_iterations and picked.any():
            d2, _ = refine(views, cand, job.keep, p.guided_radius, p.guided_eps, p.lk_iterations, reach=0.5)
            cand = d2
        d = np.where(picked, cand, d).astype(np.float32)
        stats["pairs_chosen_share"] = float(picked.mean())
    d, outliers = clean(np.clip(d, lo - 1.0, hi + 1.0).astype(np.float32))
    stats["outliers_replaced"] = int(outliers.sum())
    stats["refine_s"] = time.perf_counter() - t0
    with np.errstate(divide="ignore", invalid="ignore"):
        uniq = np.where(sw.cost > 1e-6, sw.mean_cost / np.maximum(sw.cost, 1e-6), 4.0)
    distinct = np.clip((uniq - 1.0) / 0.5, 0, 1).astype(np.float32)
    cost = np.minimum(sw.cost, TRUNCATE).astype(np.float32)
    cost[sw.no_view] = sw.cost[sw.no_view]
    return BoxEstimate(d, cost, distinct, views.texture, views.bright, sw.bound, sw.no_view)


def neighbour_count(job: SearchJob) -> int:
    return sum(neighbour(job.grid, job.ref, dx, dy) is not None for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)))
