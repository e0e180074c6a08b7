"""The pair-fusion engine (preset ``pairs``, and the ``best`` preset's fallback and second candidate): OpenCV's
semi-global matcher on each neighbouring pair (``pairs.py``), then every view decides where the pairs disagree
(a silhouette, a point one pair cannot see, a thin strip one pair smooths away)."""

from __future__ import annotations

import time
import warnings

import numpy as np
from numpy.typing import NDArray

from rigctl.depth.cost import F32, INVALID_COST, SweepLevel
from rigctl.depth.pairs import nan_median, neighbour, pair_disparity
from rigctl.depth.search import BoxEstimate, SearchJob
from rigctl.depth.sweep import sweep_engine
from rigctl.errors import ParameterError

MIN_PAIR_SIZE = 16  # OpenCV's semi-global matcher needs room for its windows and paths
CONFLICT_PX = 1.5  # pair estimates further apart than this: every view decides between them


def pairs_engine(job: SearchJob) -> BoxEstimate:
    """OpenCV's semi-global matcher on each neighbouring pair (left, right, above, below), then every view
    decides: where the pairs agree their median stands; where they disagree (a silhouette, a point one pair
    cannot see, a thin strip one pair smooths away) each pixel takes the pair estimate that the best
    ``keep`` of all views agree with, in a ``window`` around it. Only those pixels cost more than the pairs."""
    grid, ref, box, d_range, preset, stats = job.grid, job.ref, job.box, job.d_range, job.preset, job.stats
    region = job.region
    if min(grid.shape) < MIN_PAIR_SIZE:
        stats["note"] = f"image smaller than {MIN_PAIR_SIZE} px: matched by the plane sweep instead of pairs"
        return sweep_engine(job)
    t0 = time.perf_counter()
    maps = []
    u8: dict[str, NDArray[np.uint8]] = {}
    searched: list[int] = []
    work: list[int] = []
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        other = neighbour(grid, ref, dx, dy)
        if other is not None:
            maps.append(pair_disparity(grid, ref, other, d_range, box=box, u8=u8, searched=searched, work=work))
    if not maps:  # pairs need a camera on the same row or column; the plane sweep does not
        raise ParameterError(
            f"camera {ref} has no other camera on its row or column, which preset {preset.name} matches with; "
            "use --preset balanced"
        )
    stack = np.stack(maps)  # +-inf or NaN where a pair has no estimate: the median ignores all three
    n_pairs = len(maps)
    del maps  # in the stack (issue 24: not held twice)
    med, spread = nan_median(stack)
    have = ~np.isnan(med)  # some pair has an estimate (the median is NaN exactly where none has)
    # a point no pair matched (hidden from each, or outside each pair's search) takes the background side
    base = fill_from_background(np.where(have, med, np.inf).astype(np.float32), np.asarray(~have, bool))
    base = np.where(np.isfinite(base), base, 0.5 * (d_range[0] + d_range[1])).astype(np.float32)
    stats["pairs"] = n_pairs
    stats["levels"] = max(searched, default=0)  # disparities the widest pair searched, in its own pixels
    stats["pairs_s"] = time.perf_counter() - t0
    stats["pairs_pixel_levels"] = sum(work)

    t0 = time.perf_counter()
    candidates = [base] + [np.where(np.isfinite(m), m, base).astype(np.float32) for m in stack]
    # the views only as far as the candidates reach from the box (issue 24: memory), the same samples
    reach = (min(float(c.min()) for c in candidates), max(float(c.max()) for c in candidates))
    conflict = ((np.nan_to_num(spread, nan=0.0) > CONFLICT_PX) | ~have) & region
    del med, spread  # before the views are made (issue 24: memory)
    fine = SweepLevel(grid, ref, job.moving, 1.0, box, reach)
    costs = fine.costs_where(candidates, conflict, preset.window, job.keep)
    k = np.argmin(costs, axis=0)
    disp = base.copy()
    disp[conflict] = np.take_along_axis(np.stack([c[conflict] for c in candidates]), k[None], 0)[0]
    cost = np.zeros(disp.shape, np.float32)  # where the pairs agree, they are the evidence: cost 0
    cost[conflict] = np.take_along_axis(costs, k[None], 0)[0]
    stats["conflict_share"] = float(conflict.sum() / max(1, region.sum()))
    stats["select_s"] = time.perf_counter() - t0

    count = np.zeros(disp.shape, np.int64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for m in stack:  # one pair at a time (issue 24: no pairs x pixels temporaries)
            count += np.abs(m - disp) <= 1.0
    agree = count / np.float32(n_pairs)
    zeros = np.zeros(disp.shape, bool)
    no_view = cost >= INVALID_COST * 0.5
    return BoxEstimate(disp, cost, agree.astype(np.float32), fine.texture, fine.bright, zeros, no_view, ~have & region)


def fill_from_background(disp: F32, holes: NDArray[np.bool_]) -> F32:
    """Holes (inside the subject) take the farther (smaller) of the nearest valid disparities left and right
    on their row: an occluded point belongs to the background side of the edge. Only the rows with a hole
    are scanned (each row on its own: the same values; issue 24, 0.28 s a camera at 4K over every row)."""
    out = disp.copy()
    rows = np.flatnonzero(holes.any(axis=1))
    if not rows.size:
        return out
    part, gaps = disp[rows], holes[rows]
    w = disp.shape[1]
    valid = np.isfinite(part) & ~gaps
    cols = np.arange(w, dtype=np.int32)[None, :]  # 32-bit column numbers (issue 24: memory)
    left = np.maximum.accumulate(np.where(valid, cols, np.int32(-1)), axis=1)
    right = np.minimum.accumulate(np.where(valid, cols, np.int32(w))[:, ::-1], axis=1)[:, ::-1]
    at = np.arange(len(rows))[:, None]
    lv = np.where(left >= 0, part[at, np.clip(left, 0, w - 1)], np.inf)
    rv = np.where(right < w, part[at, np.clip(right, 0, w - 1)], np.inf)
    fill = np.minimum(lv, rv)
    filled = out[rows]
    filled[gaps] = fill[gaps]
    out[rows] = filled
    return out
