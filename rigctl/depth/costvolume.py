"""A multi-view cost volume that is sub-pixel accurate by construction (the ``best`` preset's engine).

1. Integer sweep over the planned range: every other camera is warped by d times its own baseline, the
   absolute difference of locally normalised intensity (gain and offset invariant) is truncated and box
   aggregated per view, each pixel keeps the best ``keep`` views (occlusion-aware view selection), and the
   combined cost is filtered by a guided filter with the reference image as guide (cost-volume filtering,
   Hosni et al. 2013: edge-aware aggregation that stays unbiased on slanted surfaces). Wide ranges are swept at
   a coarser scale first.
2. Fractional sweep: quarter-pixel candidates around the integer result, same cost, a parabola through the
   best three. After a quarter-scale sweep (whose result is only good to +-3 px) a band at half scale comes
   first (``coarse_to_fine.band``), then half-pixel candidates over +-1 px. The sweeps' order from coarse to
   fine is ``coarse_to_fine.py``; this module holds the views, the cost and one sweep.
3. Continuous refinement (``refine.py``): multi-view photometric least squares along the baselines, which has
   no preferred fractional value, so nothing locks to the sampling grid.

Memory is a few images per view, each only the part of the view that the range reaches from the crop (not
the frame): levels are streamed, never stored as a volume.
"""

from __future__ import annotations

import functools
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, overload

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.cost import (
    INVALID_COST,
    TRUNCATE,
    combine,
    exposure,
    normalise_part,
    view_part,
)
from rigctl.depth.cost_kernels import combined_costs
from rigctl.depth.feature_kernels import features_of_levels, view_features, view_levels
from rigctl.depth.grid import grey_of
from rigctl.depth.search import EstimateStats
from rigctl.depth.sweep_kernels import finish, truncate_level, update, update_reference
from rigctl.depth.visible_kernels import visible_views, visible_views_reference

F32 = NDArray[np.float32]
log = logging.getLogger(__name__)

MAX_LEVELS = 32  # integer levels swept at full resolution; a wider range is swept at a coarser scale first
# (the presenter's 48 levels at half scale: bad 1.0 1.86 % against 2.04 % at full, a quarter of the sweep's time)
FRACTION = 0.25  # step of the fractional sweep, px
# Issue 24, coarse to fine: after a quarter-scale integer sweep, a band of BAND_CANDIDATES levels one
# full-resolution px apart around it at half scale (a quarter of the pixels each), its result's 5x5 median,
# then +-BAND_REACH px by half pixels at full resolution: 7 / 4 + 5 full-resolution candidates instead of 13.
# The median gives the fine sweep a smooth start: its candidates are the start moved by a constant, so where
# the start is smooth the guided filter aggregates costs at one surface, not at a staircase of them (on the
# realistic presenter at 1920x1080 bad 0.2 falls 1.9 to 4.4 points; strips a pixel or two wide that lie more
# than a pixel from what surrounds them are left to the semi-global pairs: tests/integration/test_depth_band.py).
# BAND off: the reference path (+-3 px at full resolution), which the band is tested against.
BAND = True
BAND_SCALE = 0.5
BAND_CANDIDATES = 7
BAND_REACH = 1.0
BAND_MEDIAN = 5
# after a sweep at a quarter scale the fractional sweep must reach +-3 px: there it steps by half a pixel (13
# candidates instead of 25; the parabola and the refinement, which keeps its quarter-pixel reach, do the
# rest). Issue 24: at 1920x1080 the realistic presenter's bad 0.1 to 2.0 are all as good or better and the
# sweep takes 60 % of the time (tests/integration/test_depth_wide_step.py)
WIDE_STEP = 0.5
# matching cost: truncated intensity and gradient differences, weights and truncations of Hosni et al. (2013)
ALPHA, TAU_I, TAU_G = 0.9, 7 / 255, 2 / 255
COMPILED = True  # the matching cost by the compiled kernel; False: the OpenCV and numpy reference
OCCLUDER_PX = 1.0  # a surface nearer by more than this (disparity px) hides what lands behind it in a view
# full-resolution px by which the disparities asked of the views may leave the range: the coarse sweep's
# levels (a coarse pixel and one more beyond it), the fractional sweep's reach, the semi-global pairs' levels
# (OpenCV rounds their count up to 16, in the pair's own px: more for a pair closer than 0.5 spacings, see
# ``reach_pad``) and the refinement's half pixel
REACH_PAD = 32.0
CONTEXT_PX = 8  # full-res px beyond the reach of the filters around the estimated pixels (``cost.active_pixels``)


class MatchViews:
    """Normalised reference crop and normalised views at one scale, with warps by a disparity.

    ``reach`` (lo, hi), full-resolution px: the disparities the views will be asked for. Each view then keeps
    only the part of its frame those disparities reach from the crop (``parts``; all of it without ``reach``),
    so its memory follows the crop and the range, not the frame; a sample there is the same as in the whole
    view (the outside test stays the frame's, and the parts keep every frame edge a sample can be clamped to).
    """

    def __init__(
        self,
        images: Mapping[str, F32],
        ref: str,
        rel: dict[str, tuple[float, float]],
        box: tuple[int, int, int, int],
        scale: float = 1.0,
        centre: float = 0.0,
        reach: tuple[float, float] | None = None,
        active: NDArray[np.bool_] | None = None,
    ) -> None:
        self.scale = scale
        self.active = active  # the crop's pixels whose costs are wanted (all without it): ``combined_costs``
        self.box = tuple(round(v * scale) for v in box)
        y0, y1, x0, x1 = self.box
        self.rel = rel
        self.names = list(rel)

        def scaled_grey(n: str) -> F32:
            g = grey_of(images, n)
            if scale != 1.0:
                g = np.asarray(cv2.resize(g, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA), np.float32)
            return g

        g_ref = scaled_grey(ref)
        self.h, self.w = g_ref.shape
        self.texture = normalise_part(g_ref, (y0, y1, x0, x1))[1]
        self.guide = np.ascontiguousarray(g_ref[y0:y1, x0:x1])
        self.bright = self.guide  # the same pixels (read only)
        self.ref = view_features(g_ref, (y0, y1, x0, x1))  # cost.features, compiled (feature_kernels.py)
        # each view's part (all the same size, for the compiled cost): its top-left pixel in the view's frame
        parts = [self.part(rel[n], reach) for n in self.names]
        ph = max((b[1] - b[0] for b in parts), default=0)
        pw = max((b[3] - b[2] for b in parts), default=0)
        self.org = np.array([(min(b[0], self.h - ph), min(b[2], self.w - pw)) for b in parts], np.int64).reshape(-1, 2)
        # the views side by side for the compiled kernels: each part's intensity (matched to the reference's
        # exposure) with one pixel around it, from which the kernels make its d/dx and d/dy as
        # ``view_features`` does (issue 24: a third of the three planes' memory, the same values)
        self.levels = np.empty((len(self.names), ph + 2, pw + 2), np.float32)
        for i, n in enumerate(self.names):
            # one gain and offset per camera (exposure differences), not a local normalisation: a window
            # statistic mixes a foreground edge with the background it moves over, and moves the edge
            g = scaled_grey(n)
            gain, offset = exposure(g_ref, g, (centre * scale * rel[n][0], centre * scale * rel[n][1]))
            oy, ox = int(self.org[i, 0]), int(self.org[i, 1])
            view_levels(g, (oy, oy + ph, ox, ox + pw), out=self.levels[i], exposure=(gain, offset))
            del g
        self.rel_array = np.array([rel[n] for n in self.names], np.float64).reshape(-1, 2)

    def features(self, name: str) -> F32:
        """View ``name``'s part as intensity, d/dx and d/dy (ph x pw x 3: ``view_features``'s, bit for bit),
        made when asked (the OpenCV and numpy reference paths; the compiled kernels read ``levels``)."""
        return features_of_levels(self.levels[self.names.index(name)])

    @functools.cached_property
    def grid(self) -> tuple[F32, F32]:
        """The crop's rows and columns in the frame (gy, gx; h x w each): the reference paths' sampling grid,
        made when they ask for it (the compiled kernels place their samples themselves)."""
        y0, y1, x0, x1 = self.box
        gy, gx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
        return gy, gx

    def part(self, rel: tuple[float, float], reach: tuple[float, float] | None) -> tuple[int, int, int, int]:
        """(y0, y1, x0, x1) of a view at ``rel`` that disparities within ``reach`` (full-resolution px) sample
        from the crop (``cost.view_part``: the cost window's reach is within its margin)."""
        scaled = None if reach is None else (reach[0] * self.scale, reach[1] * self.scale)
        y0, y1, x0, x1 = self.box
        return view_part((y0, y1, x0, x1), (self.h, self.w), rel, scaled)

    @property
    def shape(self) -> tuple[int, int]:
        return self.ref.shape[0], self.ref.shape[1]

    def warp(self, name: str, d: float | F32) -> tuple[F32, NDArray[np.bool_]]:
        """View ``name`` sampled where the reference's pixels lie at disparity ``d`` (a number or a map), and
        where that falls outside the view."""
        rx, ry = self.rel[name]
        oy, ox = (int(v) for v in self.org[self.names.index(name)])
        if isinstance(d, float):
            y0, y1, x0, x1 = self.box
            m = np.array([[1, 0, x0 - d * rx], [0, 1, y0 - d * ry]], np.float32)
            m[0, 2] -= np.float32(ox)  # in the part (exact: an integer off a float32 of at most this size)
            m[1, 2] -= np.float32(oy)
            out = cv2.warpAffine(
                self.features(name),
                m,
                (x1 - x0, y1 - y0),
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_REPLICATE,
            )
            gy, gx = self.grid
            xs, ys = gx[0] - d * rx, gy[:, 0] - d * ry
            outside = ((ys < 0) | (ys > self.h - 1))[:, None] | ((xs < 0) | (xs > self.w - 1))[None, :]
            return np.asarray(out, np.float32), np.asarray(outside)
        gy, gx = self.grid
        mx, my = gx - d * np.float32(rx), gy - d * np.float32(ry)
        feat = self.features(name)
        mx0, my0 = mx - np.float32(ox), my - np.float32(oy)
        out = cv2.remap(feat, mx0, my0, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return np.asarray(out, np.float32), np.asarray((mx < 0) | (mx > self.w - 1) | (my < 0) | (my > self.h - 1))

    def visible_count(
        self, d: F32, front: NDArray[np.bool_], tol: float = OCCLUDER_PX, where: NDArray[np.bool_] | None = None
    ) -> NDArray[np.int32]:
        """How many views see the point at disparity ``d`` (a map): it lies inside the view's frame and no
        ``front`` pixel of the reference lands on the same place in that view with a disparity more than
        ``tol`` larger (a nearer surface covers it there: the bands behind a foreground edge). The occluders
        are what the reference itself sees (its estimated disparity), splatted on the view by the largest
        disparity (a z-buffer); a pixel is hidden when all four cells around its place are nearer. Counted
        only at ``where`` when given (0 elsewhere). With ``COMPILED`` off, by the numpy reference."""
        y0, _, x0, _ = self.box
        if COMPILED:
            count = visible_views(d, front, self.rel_array, (y0, x0), (self.h, self.w), tol, where)
            return np.asarray(count, np.int32)
        n = visible_views_reference(d, front, list(self.rel.values()), self.grid, (self.h, self.w), tol)
        return n if where is None else np.where(where, n, 0).astype(np.int32)

    def costs(self, d: float | F32, win: int, keep: int) -> F32:
        """The combined cost at ``d`` (a number or a map): the mean of the ``keep`` best views'
        ``view_costs``, computed in one compiled pass (``cost_kernels.py``); with ``COMPILED`` off, by the
        OpenCV and numpy reference."""
        if not COMPILED or not self.names:
            return combine(self.view_costs(d, win), keep)
        y0, _, x0, _ = self.box
        weights = ((1 - ALPHA) * TRUNCATE / TAU_I, ALPHA * TRUNCATE / TAU_G, TAU_I, TAU_G)
        return combined_costs(
            self.levels,
            self.ref,
            self.rel_array,
            d,
            (y0, x0),
            win,
            keep,
            weights,
            INVALID_COST,
            self.org,
            (self.h, self.w),
            self.active,
        )

    def view_costs(self, d: float | F32, win: int) -> F32:
        """(views, h, w): truncated absolute differences of intensity and gradient (Hosni et al.'s cost, scaled
        to 0..TRUNCATE), box aggregated per view; INVALID outside the view."""
        out = np.empty((len(self.names), *self.shape), np.float32)
        for i, n in enumerate(self.names):
            warped, outside = self.warp(n, d)
            diff = np.abs(warped - self.ref)
            ad = np.minimum(diff[..., 0], TAU_I) * np.float32((1 - ALPHA) * TRUNCATE / TAU_I)
            ad += np.minimum(diff[..., 1] + diff[..., 2], TAU_G) * np.float32(ALPHA * TRUNCATE / TAU_G)
            agg = cv2.boxFilter(ad, -1, (win, win), borderType=cv2.BORDER_REFLECT)
            agg[outside] = INVALID_COST
            out[i] = agg
        return out


@dataclass(frozen=True)
class VolumeParams:
    keep: int  # views kept per pixel
    window: int = 3  # per-view box window before view selection (px, odd)
    radius: int = 4  # guided filter radius (px at full resolution)
    eps: float = 1e-4  # guided filter regularisation (grey levels in 0..1, squared)


class Aggregator:
    """Cost-volume filtering: the guided filter with the reference image as guide, its statistics computed
    once per camera (OpenCV's implementation, one pass per slice)."""

    def __init__(self, guide: F32, radius: int, eps: float) -> None:
        self.radius = max(1, radius)
        self.filter: Any = None
        if min(guide.shape) > 2 * self.radius:
            self.filter = cv2.ximgproc.createGuidedFilter(np.ascontiguousarray(guide), self.radius, eps)

    def __call__(self, cost: F32) -> F32:
        return self.smooth(np.minimum(cost, TRUNCATE))  # an invisible level must not spread INVALID around

    def smooth(self, c: F32) -> F32:
        c = np.ascontiguousarray(c, np.float32)
        if self.filter is None:
            k = 2 * self.radius + 1
            return np.asarray(cv2.boxFilter(c, -1, (k, k), borderType=cv2.BORDER_REFLECT), np.float32)
        return np.asarray(self.filter.filter(c), np.float32)


@dataclass
class Sweep:
    disparity: F32
    cost: F32  # aggregated cost of the chosen match
    mean_cost: F32  # the average over candidates (distinctiveness: mean / best)
    bound: NDArray[np.bool_]  # the best lay at the first or last level
    no_view: NDArray[np.bool_]  # no view sees the point at the chosen disparity


def sweep(
    views: MatchViews,
    candidates: Sequence[float | F32],
    p: VolumeParams,
    win: int,
    radius: int,
    stats: EstimateStats | None = None,
) -> Sweep:
    """Winner-take-all over ``candidates`` (constant disparities or per-pixel maps, in increasing order),
    streamed, with the costs of the best's two neighbours kept for a parabola fit. ``stats`` adds the
    seconds spent on the matching cost and on its aggregation (``cost_s``, ``aggregation_s``)."""
    agg = Aggregator(views.guide, radius, p.eps)
    t_cost = t_agg = 0.0
    shape = views.shape
    best = np.full(shape, np.inf, np.float32)
    k_best = np.zeros(shape, np.int32)
    c_minus = np.full(shape, np.inf, np.float32)
    c_plus = np.full(shape, np.inf, np.float32)
    total = np.zeros(shape, np.float32)
    prev = np.full(shape, np.inf, np.float32)
    seen_any = np.zeros(shape, bool)
    state = (best, k_best, c_minus, c_plus, total, seen_any)  # updated in place (no per-level copies of it)
    for k, d in enumerate(candidates):
        t0 = time.perf_counter()
        raw = views.costs(d, win, p.keep)
        t1 = time.perf_counter()
        if COMPILED:  # truncated and where a view saw it in one pass, the bookkeeping in one (sweep_kernels.py)
            clipped, seen = truncate_level(raw, TRUNCATE, INVALID_COST)
            del raw
            prev = update(agg.smooth(clipped), seen, k, prev, state, INVALID_COST, TRUNCATE)
        else:
            seen = raw < INVALID_COST * 0.5
            prev = update_reference(agg(raw), seen, k, prev, state, INVALID_COST, TRUNCATE)
            del raw
        t_agg += time.perf_counter() - t1
        t_cost += t1 - t0
    if stats is not None:
        stats["cost_s"] = stats.get("cost_s", 0.0) + t_cost
        stats["aggregation_s"] = stats.get("aggregation_s", 0.0) + t_agg
    if COMPILED and len(candidates) and (base := _base_and_offsets(candidates)) is not None:
        disp, mean, bound, no_view = finish(state, *base, INVALID_COST)
        return Sweep(disp, best, mean, bound, no_view)
    return finish_reference(candidates, state)


def _base_and_offsets(candidates: Sequence[float | F32]) -> tuple[F32 | None, F32] | None:
    """The candidates as the compiled finish takes them (``sweep_kernels.finish``): a base map and offsets
    (``Around``), or the levels alone (constant disparities); None for a list of maps."""
    if isinstance(candidates, Around):
        return candidates.base, candidates.offsets
    if all(isinstance(c, float) for c in candidates):
        return None, np.asarray(candidates, np.float32)
    return None


def finish_reference(
    candidates: Sequence[float | F32], state: tuple[F32, NDArray[np.int32], F32, F32, F32, NDArray[np.bool_]]
) -> Sweep:
    """The sweep's result from its state in numpy (the reference ``sweep_kernels.finish`` matches): the best
    candidate moved by the parabola through its neighbours' costs, at most half a step."""
    best, k_best, c_minus, c_plus, total, seen_any = state
    shape = best.shape
    n = len(candidates)
    stack_at = _pick(candidates, k_best, shape)
    step = _pick(candidates, np.minimum(k_best + 1, n - 1), shape) - _pick(candidates, np.maximum(k_best - 1, 0), shape)
    interior = np.isfinite(c_minus) & np.isfinite(c_plus) & (c_minus < INVALID_COST) & (c_plus < INVALID_COST)
    den = c_minus + c_plus - 2 * best
    ok = interior & (den > 1e-9)
    with np.errstate(divide="ignore", invalid="ignore"):
        sub = np.where(ok, 0.5 * (c_minus - c_plus) / np.where(ok, den, 1.0), 0.0)
    sub = np.clip(sub, -0.5, 0.5) * np.where(ok, step * 0.5, 0.0)
    disp = (stack_at + sub).astype(np.float32)
    bound = ((k_best == 0) | (k_best == n - 1)) if n > 2 else np.zeros(shape, bool)
    return Sweep(disp, best, total / np.float32(max(n, 1)), np.asarray(bound), ~seen_any | (best >= INVALID_COST * 0.5))


class Around(Sequence[F32]):
    """The fractional sweep's candidates: ``base`` moved by k times ``step`` for k = -n..n, each map made when
    asked for (issue 24: not 2 n + 1 maps held at once), the same values as a list of them."""

    def __init__(self, base: F32, step: float, n: int) -> None:
        self.base = base
        self.offsets = np.array([np.float32(k * step) for k in range(-n, n + 1)], np.float32)

    def __len__(self) -> int:
        return len(self.offsets)

    @overload
    def __getitem__(self, i: int) -> F32: ...

    @overload
    def __getitem__(self, i: slice) -> Sequence[F32]: ...

    def __getitem__(self, i: int | slice) -> F32 | Sequence[F32]:
        if isinstance(i, slice):
            return [self[j] for j in range(len(self))[i]]
        return (self.base + self.offsets[i]).astype(np.float32)

    def pick(self, k: NDArray[np.int32]) -> F32:
        """Per pixel, candidate k's value."""
        return (self.base + self.offsets[k]).astype(np.float32)


def _pick(candidates: Sequence[float | F32], k: NDArray[np.int32], shape: tuple[int, int]) -> F32:
    if isinstance(candidates, Around):
        return candidates.pick(k)
    if all(isinstance(c, float) for c in candidates):
        return np.asarray(np.asarray(candidates, np.float32)[k], np.float32)
    out = np.empty(shape, np.float32)
    for i, c in enumerate(candidates):
        sel = k == i
        out[sel] = c[sel] if isinstance(c, np.ndarray) else c
    return out
