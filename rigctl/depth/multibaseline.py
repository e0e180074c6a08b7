"""Multi-baseline depth for one camera of a rectified grid, using every other camera with its own baseline.

Candidates are indexed by the disparity d of the horizontal spacing; camera b is sampled at
(x - d (ox_b - ox_a), y - d (oy_b - oy_a)) (so a vertical neighbour moves by d * dy/dx). Matching cost: the
absolute difference of locally normalised intensity (invariant to the cameras' gain and offset differences),
truncated, averaged over a box window, and per pixel only the best half of the views is kept (a point hidden
from some cameras is seen by others: occlusion-aware view selection). The search streams over the planned
disparity range at half resolution, then refines around the upsampled result at full resolution with a
guarded parabola for sub-pixel precision. Only the keyed subject's bounding box is searched. Memory is a few
images per view, whatever the range.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import Grid
from rigctl.depth.key import Keyer, subject_box
from rigctl.depth.pairs import nan_median, neighbour, pair_disparity
from rigctl.errors import ParameterError

F32 = NDArray[np.float32]
INVALID_COST = 1e3
DEFAULT_KEYER = Keyer()
TRUNCATE = 1.5  # normalised-intensity difference above this is an occlusion or a mismatch, not more
MIN_PAIR_SIZE = 16  # OpenCV's semi-global matcher needs room for its windows and paths
CONFLICT_PX = 1.5  # pair estimates further apart than this: every view decides between them


@dataclass(frozen=True)
class Preset:
    name: str
    views: str  # "horizontal": left and right neighbours; "neighbours": the 8 around; "all": every camera
    keep: float  # share of views kept per pixel (the best ones); 0: the best side (left, right, above, below)
    window: int  # aggregation window (full resolution, pixels)
    refine: bool  # full-resolution refinement (else: half resolution upsampled)
    radius: int = 2  # refinement search radius around the coarse result, px
    cross_check: bool = False
    median: int = 0  # median filter of the result (0: none)
    sgm: tuple[float, float] | None = None  # semi-global smoothing at half resolution: (P1, P2) penalties
    sgm_fine: tuple[float, float] | None = None  # the same over the full-resolution refinement candidates
    engine: str = "sweep"  # "sweep": plane sweep; "pairs": OpenCV SGBM per pair, fused; "volume": costvolume.py
    guided_radius: int = 4  # "volume": guided-filter radius of the cost-volume filtering, px
    guided_eps: float = 1e-4  # "volume": its regularisation (grey levels 0..1, squared)
    with_pairs: bool = True  # "volume": the semi-global pairs are a second candidate, chosen per pixel by cost
    lk_iterations: int = 3  # "volume": Gauss-Newton steps of the continuous refinement along the baselines
    description: str = ""


PRESETS = {
    p.name: p
    for p in (
        Preset("fast", "neighbours", 0.5, 7, refine=False, median=3, description="half resolution, 8 neighbours"),
        Preset(
            "balanced",
            "neighbours",
            0.375,
            3,
            refine=True,
            median=3,
            sgm=(0.05, 0.4),
            sgm_fine=(0.05, 0.3),
            description="coarse-to-fine with semi-global smoothing, 8 neighbours",
        ),
        Preset(
            "best",
            "all",
            0.5,
            3,
            refine=True,
            engine="volume",
            description="multi-view cost volume over the planned range, guided-filter aggregation, best half of "
            "the views per pixel, quarter-pixel sweep, continuous least-squares refinement along the baselines",
        ),
        Preset(
            "pairs",
            "all",
            0.375,
            7,
            refine=True,
            median=5,
            cross_check=True,
            engine="pairs",
            description="OpenCV's semi-global matcher on every neighbouring pair, every camera decides where the "
            "pairs disagree, cross-checked between cameras",
        ),
    )
}


@dataclass
class DepthResult:
    disparity: F32  # +inf where there is no estimate (keyed background, outside every view)
    confidence: F32  # 0..1
    unreliable: NDArray[np.bool_]  # textureless or saturated: an estimate, not to be trusted
    bound_hit: NDArray[np.bool_]  # the best match lay at the edge of the planned range
    matte: F32
    filled: NDArray[np.bool_] = field(default_factory=lambda: np.zeros((0, 0), bool))
    stats: dict[str, Any] = field(default_factory=dict)


def _grey(rgb: F32) -> F32:
    return np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), dtype=np.float32)


def _normalise(grey: F32, win: int = 7) -> tuple[F32, F32]:
    """Locally normalised intensity, and the local standard deviation (texture)."""
    mean = cv2.boxFilter(grey, -1, (win, win), borderType=cv2.BORDER_REFLECT)
    sq = cv2.boxFilter(grey * grey, -1, (win, win), borderType=cv2.BORDER_REFLECT)
    std = np.sqrt(np.maximum(sq - mean * mean, 0.0))
    return np.asarray((grey - mean) / (std + 0.01), dtype=np.float32), np.asarray(std, dtype=np.float32)


def _views(grid: Grid, ref: str, mode: str) -> list[str]:
    ox, oy = grid.offsets[ref]
    others = [n for n in grid.names if n != ref]
    if mode == "all":
        return others
    # grid steps: the smallest offsets that are a real step, not a camera mounted a fraction of a mm off
    steps = [abs(grid.offsets[n][0] - ox) for n in others if abs(grid.offsets[n][0] - ox) > 0.2]
    sx = min(steps) if steps else 1.0
    vsteps = [abs(grid.offsets[n][1] - oy) for n in others if abs(grid.offsets[n][1] - oy) > 0.2]
    sy = min(vsteps) if vsteps else 1.0
    out = []
    for n in others:
        dx, dy = (grid.offsets[n][0] - ox) / sx, (grid.offsets[n][1] - oy) / sy
        if (mode == "horizontal" and abs(dy) < 0.25 and abs(abs(dx) - 1) < 0.25) or (
            mode == "neighbours" and max(abs(dx), abs(dy)) < 1.25
        ):
            out.append(n)
    return out or others


class _Level:
    """Normalised images of the reference crop and of every view, at one scale."""

    def __init__(self, grid: Grid, ref: str, views: list[str], scale: float, box: tuple[int, int, int, int]) -> None:
        self.scale = scale
        y0, y1, x0, x1 = (round(v * scale) for v in box)
        self.box = (y0, y1, x0, x1)
        self.size = (x1 - x0, y1 - y0)
        self.norm: dict[str, F32] = {}
        grey = {}
        for n in [ref, *views]:
            g = _grey(grid.images[n])
            if scale != 1.0:
                g = np.asarray(cv2.resize(g, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA), np.float32)
            grey[n] = g
            self.norm[n], std = _normalise(g)
            if n == ref:
                self.texture = std[y0:y1, x0:x1]
                self.bright = g[y0:y1, x0:x1]
        self.h, self.w = grey[ref].shape
        self.ref = self.norm[ref][y0:y1, x0:x1]
        ox, oy = grid.offsets[ref]
        self.rel = {n: (grid.offsets[n][0] - ox, grid.offsets[n][1] - oy) for n in views}
        self.views = views

    def cost_const(self, d: float, win: int) -> F32:
        """(views, h, w) aggregated cost at one disparity for every pixel."""
        y0, y1, x0, x1 = self.box
        out = np.empty((len(self.views), y1 - y0, x1 - x0), np.float32)
        xs = np.arange(x0, x1, dtype=np.float32)
        ys = np.arange(y0, y1, dtype=np.float32)
        for i, n in enumerate(self.views):
            rx, ry = self.rel[n]
            M = np.array([[1, 0, x0 - d * rx], [0, 1, y0 - d * ry]], np.float32)
            warped = cv2.warpAffine(
                self.norm[n],
                M,
                self.size,
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_REPLICATE,
            )
            ad = np.minimum(np.abs(warped - self.ref), TRUNCATE)
            agg = cv2.boxFilter(ad, -1, (win, win), borderType=cv2.BORDER_REFLECT)
            inside_x = (xs - d * rx >= 0) & (xs - d * rx <= self.w - 1)
            inside_y = (ys - d * ry >= 0) & (ys - d * ry <= self.h - 1)
            agg[~inside_y, :] = INVALID_COST
            agg[:, ~inside_x] = INVALID_COST
            out[i] = agg
        return out

    def cost_map(self, D: F32, win: int) -> F32:
        """(views, h, w) aggregated cost at a per-pixel disparity map D (crop-sized)."""
        y0, y1, x0, x1 = self.box
        gy, gx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
        out = np.empty((len(self.views), y1 - y0, x1 - x0), np.float32)
        for i, n in enumerate(self.views):
            rx, ry = self.rel[n]
            mx = gx - D * np.float32(rx)
            my = gy - D * np.float32(ry)
            warped = cv2.remap(self.norm[n], mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            ad = np.minimum(np.abs(warped - self.ref), TRUNCATE)
            agg = cv2.boxFilter(ad, -1, (win, win), borderType=cv2.BORDER_REFLECT)
            outside = (mx < 0) | (mx > self.w - 1) | (my < 0) | (my > self.h - 1)
            agg[outside] = INVALID_COST
            out[i] = agg
        return out

    def costs_where(self, candidates: list[F32], where: NDArray[np.bool_], win: int, keep: int) -> F32:
        """(candidates, pixels) combined cost of each candidate disparity map at the pixels of ``where`` only:
        each view is sampled at those pixels and their ``win`` neighbourhood, not over the whole crop."""
        y0, _, x0, _ = self.box
        need = np.asarray(cv2.dilate(where.astype(np.uint8), np.ones((win, win), np.uint8)), bool)
        ys, xs = np.nonzero(need)
        n = ys.size
        width = 4096  # cv2.remap takes maps below 32767 in each dimension: lay the pixels out in rows
        rows = -(-n // width) if n else 1
        pad = rows * width - n
        gx = np.pad((xs + x0).astype(np.float32), (0, pad)).reshape(rows, width)
        gy = np.pad((ys + y0).astype(np.float32), (0, pad)).reshape(rows, width)
        ref_vals = self.ref[ys, xs]
        qy, qx = np.nonzero(where)
        nv = len(self.views)
        out = np.empty((len(candidates), qy.size), np.float32)
        # views in groups of four channels: one scatter and one box filter aggregates four views at once
        dense = [np.zeros((*where.shape, 4), np.float32) for _ in range(0, nv, 4)]
        ad = np.zeros((n, 4 * len(dense)), np.float32)  # channels past the last view stay 0
        per_view = np.empty((nv, qy.size), np.float32)
        for ci, cand in enumerate(candidates):
            d = np.pad(cand[ys, xs], (0, pad)).reshape(rows, width)
            dq = cand[qy, qx]
            for vi, name in enumerate(self.views):
                rx, ry = self.rel[name]
                mx, my = gx - d * np.float32(rx), gy - d * np.float32(ry)
                warped = cv2.remap(self.norm[name], mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                ad[:, vi] = warped.reshape(-1)[:n]
            np.subtract(ad, ref_vals[:, None], out=ad)
            np.abs(ad, out=ad)
            np.minimum(ad, TRUNCATE, out=ad)
            for gi, img in enumerate(dense):
                img[ys, xs] = ad[:, 4 * gi : 4 * gi + 4]
                agg = cv2.boxFilter(img, -1, (win, win), borderType=cv2.BORDER_REFLECT)[qy, qx]
                take = min(4, nv - 4 * gi)
                per_view[4 * gi : 4 * gi + take] = agg[:, :take].T
            for vi, name in enumerate(self.views):
                rx, ry = self.rel[name]
                cx, cy = qx + x0 - dq * np.float32(rx), qy + y0 - dq * np.float32(ry)
                per_view[vi][(cx < 0) | (cx > self.w - 1) | (cy < 0) | (cy > self.h - 1)] = INVALID_COST
            out[ci] = _combine(per_view, keep)
        return out


def _groups(level: _Level) -> list[list[int]]:
    """Views on each side of the reference (left, right, above, below): a point hidden by a foreground edge
    is hidden on one side only, so one of the sides sees it in every view."""
    eps = 1e-6
    sides = [
        [i for i, n in enumerate(level.views) if level.rel[n][0] < -eps],
        [i for i, n in enumerate(level.views) if level.rel[n][0] > eps],
        [i for i, n in enumerate(level.views) if level.rel[n][1] < -eps],
        [i for i, n in enumerate(level.views) if level.rel[n][1] > eps],
    ]
    return [g for g in sides if g]


def _combine(costs: F32, keep: int, groups: list[list[int]] | None = None) -> F32:
    """Per pixel: the best side's mean cost (``groups``), or the mean of the ``keep`` smallest view costs
    (occluded views drop out)."""
    if groups:
        out = costs[groups[0]].mean(0)
        for g in groups[1:]:
            np.minimum(out, costs[g].mean(0), out=out)
        return np.asarray(out, dtype=np.float32)
    part = costs if keep >= costs.shape[0] else np.partition(costs, keep - 1, axis=0)[:keep]
    # views that cannot see the point (outside their image) do not count; a pixel only one view sees
    # is matched with that view alone
    seen = part < INVALID_COST * 0.5
    n = seen.sum(0)
    total = np.where(seen, part, 0).sum(0)
    return np.asarray(np.where(n > 0, total / np.maximum(n, 1), INVALID_COST), dtype=np.float32)


def _sgm_path(C: F32, p1: float, p2: float, reverse: bool) -> F32:
    """One semi-global path over axis 0 of C (steps, D, N): L = C + min(L', L'(d +- 1) + p1, min L' + p2) - min L'."""
    L = np.empty_like(C)
    order = range(C.shape[0] - 1, -1, -1) if reverse else range(C.shape[0])
    prev = None
    big = np.float32(1e9)
    for i in order:
        if prev is None:
            L[i] = C[i]
        else:
            m = prev.min(0)
            up = np.empty_like(prev)
            up[1:] = prev[:-1]
            up[0] = big
            down = np.empty_like(prev)
            down[:-1] = prev[1:]
            down[-1] = big
            best = np.minimum(np.minimum(prev, np.minimum(up, down) + p1), m + p2)
            L[i] = C[i] + best - m
        prev = L[i]
    return L


def semi_global(volume: F32, p1: float, p2: float) -> F32:
    """Four-path semi-global aggregation of a (D, H, W) cost volume (left/right, up/down)."""
    h_vol = np.ascontiguousarray(volume.transpose(2, 0, 1))  # (W, D, H)
    total = _sgm_path(h_vol, p1, p2, False) + _sgm_path(h_vol, p1, p2, True)
    out = np.ascontiguousarray(total.transpose(1, 2, 0))
    v_vol = np.ascontiguousarray(volume.transpose(1, 0, 2))  # (H, D, W)
    total_v = _sgm_path(v_vol, p1, p2, False) + _sgm_path(v_vol, p1, p2, True)
    out += total_v.transpose(1, 0, 2)
    return np.asarray(out, dtype=np.float32)


def _odd(n: float) -> int:
    k = max(3, round(n))
    return k if k % 2 else k + 1


@dataclass
class _Crop:
    """What an engine found inside the searched box (all arrays box-sized)."""

    disparity: F32
    cost: F32  # the chosen match's aggregated cost (0 perfect, TRUNCATE no match)
    distinct: F32  # 0..1: how clearly the match stands out (or how well the estimates agree)
    texture: F32
    bright: F32
    bound: NDArray[np.bool_]  # the coarse search's best lay at the planned range's edge
    no_view: NDArray[np.bool_]  # no other camera sees the point
    filled: NDArray[np.bool_] | None = None  # no match found: filled from the background side


@dataclass
class _Search:
    """One camera's search: the views it matches with, the box searched, the range, the preset."""

    grid: Grid
    ref: str
    moving: list[str]
    box: tuple[int, int, int, int]
    d_range: tuple[float, float]
    keep: int
    preset: Preset
    stats: dict[str, Any]
    region: NDArray[np.bool_]  # box-sized: the pixels to estimate (the keyed subject)


def _sweep_engine(job: _Search) -> _Crop:
    """Our own plane sweep over the planned range at half resolution, refined at full resolution."""
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
    coarse = _Level(grid, ref, moving, scale, box)
    win_c = _odd(preset.window * scale)
    levels = np.arange(math.floor(lo * scale) - 1, math.ceil(hi * scale) + 2, 1.0, dtype=np.float32)
    levels = levels[: max(1, min(len(levels), 4 * max(coarse.h, coarse.w)))]  # a range beyond the image is capped
    stats["levels"] = len(levels)
    groups_c = _groups(coarse) if preset.keep == 0 else None
    best = np.full(coarse.ref.shape, np.inf, np.float32)
    best_d = np.zeros(coarse.ref.shape, np.float32)
    total = np.zeros(coarse.ref.shape, np.float32)
    volume = np.empty((len(levels), *coarse.ref.shape), np.float32) if preset.sgm else None
    for i, d in enumerate(levels):
        c = _combine(coarse.cost_const(float(d), win_c), keep, groups_c)
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
        fine = _Level(grid, ref, moving, 1.0, box)
        r = preset.radius
        groups_f = _groups(fine) if preset.keep == 0 else None
        costs = np.stack(
            [_combine(fine.cost_map(D0 + np.float32(k), preset.window), keep, groups_f) for k in range(-r, r + 1)]
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
        sub = np.clip(sub, -0.5, 0.5)  # guarded: the parabola never moves the match by more than half a step
        disp = D0 + (k_best - r).astype(np.float32) + sub.astype(np.float32)
        cost = c0
        texture = fine.texture
        bright = fine.bright
        bound_full = cv2.resize(bound.astype(np.uint8), (crop_w, crop_h), interpolation=cv2.INTER_NEAREST).astype(bool)
        no_view_full = cv2.resize(no_view.astype(np.uint8), (crop_w, crop_h), interpolation=cv2.INTER_NEAREST).astype(
            bool
        )
        uniq = cv2.resize(second / np.maximum(best, 1e-6), (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
    else:
        disp = cv2.resize(best_d / scale, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
        cost = cv2.resize(best, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
        texture = np.asarray(cv2.resize(coarse.texture, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR), np.float32)
        bright = np.asarray(cv2.resize(coarse.bright, (crop_w, crop_h), interpolation=cv2.INTER_LINEAR), np.float32)
        bound_full = cv2.resize(bound.astype(np.uint8), (crop_w, crop_h), interpolation=cv2.INTER_NEAREST).astype(bool)
        no_view_full = cv2.resize(no_view.astype(np.uint8), (crop_w, crop_h), interpolation=cv2.INTER_NEAREST).astype(
            bool
        )
        uniq = cv2.resize(second / np.maximum(best, 1e-6), (crop_w, crop_h), interpolation=cv2.INTER_LINEAR)
    stats["refine_s"] = time.perf_counter() - t0
    distinct = np.clip((np.nan_to_num(uniq, posinf=4.0) - 1.0) / 0.5, 0, 1).astype(np.float32)
    return _Crop(
        np.asarray(disp, np.float32), np.asarray(cost, np.float32), distinct, texture, bright, bound_full, no_view_full
    )


def _pairs_engine(job: _Search) -> _Crop:
    """OpenCV's semi-global matcher on each neighbouring pair (left, right, above, below), then every view
    decides: where the pairs agree their median stands; where they disagree (a silhouette, a point one pair
    cannot see, a thin strip one pair smooths away) each pixel takes the pair estimate that the best
    ``keep`` of all views agree with, in a ``window`` around it. Only those pixels cost more than the pairs."""
    grid, ref, box, d_range, preset, stats = job.grid, job.ref, job.box, job.d_range, job.preset, job.stats
    region = job.region
    if min(grid.shape) < MIN_PAIR_SIZE:
        stats["note"] = f"image smaller than {MIN_PAIR_SIZE} px: matched by the plane sweep instead of pairs"
        return _sweep_engine(job)
    t0 = time.perf_counter()
    maps = []
    u8: dict[str, NDArray[np.uint8]] = {}
    searched: list[int] = []
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        other = neighbour(grid, ref, dx, dy)
        if other is not None:
            maps.append(pair_disparity(grid, ref, other, d_range, box=box, u8=u8, searched=searched))
    if not maps:  # pairs need a camera on the same row or column; the plane sweep does not
        raise ParameterError(
            f"camera {ref} has no other camera on its row or column, which preset {preset.name} matches with; "
            "use --preset balanced"
        )
    stack = np.stack(maps)
    stack[~np.isfinite(stack)] = np.nan
    have = np.isfinite(stack).any(0)
    med, spread = nan_median(stack)
    # a point no pair matched (hidden from each, or outside each pair's search) takes the background side
    base = fill_from_background(np.where(have, med, np.inf).astype(np.float32), np.asarray(~have, bool))
    base = np.where(np.isfinite(base), base, 0.5 * (d_range[0] + d_range[1])).astype(np.float32)
    stats["pairs"] = len(maps)
    stats["levels"] = max(searched, default=0)  # disparities the widest pair searched, in its own pixels
    stats["pairs_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    fine = _Level(grid, ref, job.moving, 1.0, box)
    candidates = [base] + [np.where(np.isfinite(m), m, base).astype(np.float32) for m in stack]
    conflict = ((np.nan_to_num(spread, nan=0.0) > CONFLICT_PX) | ~have) & region
    costs = fine.costs_where(candidates, conflict, preset.window, job.keep)
    k = np.argmin(costs, axis=0)
    disp = base.copy()
    disp[conflict] = np.take_along_axis(np.stack([c[conflict] for c in candidates]), k[None], 0)[0]
    cost = np.zeros(disp.shape, np.float32)  # where the pairs agree, they are the evidence: cost 0
    cost[conflict] = np.take_along_axis(costs, k[None], 0)[0]
    stats["conflict_share"] = float(conflict.sum() / max(1, region.sum()))
    stats["select_s"] = time.perf_counter() - t0

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        agree = (np.abs(stack - disp[None]) <= 1.0).sum(0) / np.float32(len(maps))
    zeros = np.zeros(disp.shape, bool)
    no_view = cost >= INVALID_COST * 0.5
    return _Crop(disp, cost, agree.astype(np.float32), fine.texture, fine.bright, zeros, no_view, ~have & region)


def estimate(
    grid: Grid,
    ref: str,
    d_range: tuple[float, float],
    preset: Preset,
    keyer: Keyer | None = DEFAULT_KEYER,
    matte: F32 | None = None,
) -> DepthResult:
    """Disparity of camera ``ref``. ``keyer`` None: no keying (every pixel is searched)."""
    t_start = time.perf_counter()
    if ref not in grid.images:
        raise ParameterError(f"camera {ref} is not in the grid (it has {', '.join(grid.names)})")
    lo, hi = float(d_range[0]), float(d_range[1])
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
        raise ParameterError(f"disparity range must be finite with min <= max, got {d_range}")
    h, w = grid.shape
    stats: dict[str, Any] = {"camera": ref, "preset": preset.name}
    t0 = time.perf_counter()
    if matte is None:
        matte = keyer.matte(grid.images[ref]) if keyer is not None else np.ones((h, w), np.float32)
    fg = matte > 0.0  # the soft edge too: compositing needs depth under a partly transparent edge
    stats["key_s"] = time.perf_counter() - t0
    stats["keyed_background_share"] = float(1.0 - fg.mean())
    empty = DepthResult(
        np.full((h, w), np.inf, np.float32),
        np.zeros((h, w), np.float32),
        np.zeros((h, w), bool),
        np.zeros((h, w), bool),
        matte,
        np.zeros((h, w), bool),
        stats,
    )
    views = _views(grid, ref, preset.views)
    moving = [
        n
        for n in views
        if max(abs(grid.offsets[n][0] - grid.offsets[ref][0]), abs(grid.offsets[n][1] - grid.offsets[ref][1])) > 1e-9
    ]
    stats["views"] = moving
    if not fg.any() or not moving:
        stats["note"] = "every pixel keyed as background" if not fg.any() else "no camera at a different position"
        stats["seconds"] = time.perf_counter() - t_start
        return empty
    box = subject_box(fg, margin=preset.window)
    assert box is not None
    stats["searched_share"] = float((box[1] - box[0]) * (box[3] - box[2]) / (h * w))
    keep = max(1, math.ceil(preset.keep * len(moving)))

    y0, y1, x0, x1 = box
    job = _Search(grid, ref, moving, box, (lo, hi), keep, preset, stats, fg[y0:y1, x0:x1])
    if preset.engine == "volume":
        from rigctl.depth.volume_engine import volume_engine  # it builds on this module's pairs engine

        crop = volume_engine(job)
    else:
        crop = _pairs_engine(job) if preset.engine == "pairs" else _sweep_engine(job)
    disp = crop.disparity
    if preset.median:
        disp = np.asarray(cv2.medianBlur(np.ascontiguousarray(disp, dtype=np.float32), preset.median), np.float32)

    out = np.full((h, w), np.inf, np.float32)
    region = fg[y0:y1, x0:x1]
    valid = region & ~crop.no_view & np.isfinite(disp)
    out[y0:y1, x0:x1] = np.where(valid, disp, np.inf)
    conf = np.zeros((h, w), np.float32)
    c_local = np.clip(1.0 - crop.cost / TRUNCATE, 0, 1) * crop.distinct
    unreliable_local = (crop.texture < 0.01) | (crop.bright > 0.98)
    conf[y0:y1, x0:x1] = np.where(valid & ~unreliable_local, c_local, 0.0)
    unreliable = np.zeros((h, w), bool)
    unreliable[y0:y1, x0:x1] = valid & unreliable_local
    bound_hit = np.zeros((h, w), bool)
    # the match lies at the edge of the planned range: the truth may lie beyond it
    at_edge = (disp >= hi - 0.5) | (disp <= lo + 0.5)
    bound_hit[y0:y1, x0:x1] = valid & (crop.bound | at_edge)
    stats.update(
        seconds=time.perf_counter() - t_start,
        estimated_share_of_subject=float(valid.sum() / max(1, fg.sum())),
        bound_hit_pixels=int(bound_hit.sum()),
        unreliable_pixels=int(unreliable.sum()),
    )
    filled = np.zeros((h, w), bool)
    if crop.filled is not None:
        filled[y0:y1, x0:x1] = valid & crop.filled
        stats["filled_from_background_pixels"] = int(filled.sum())
    return DepthResult(out, conf, unreliable, bound_hit, matte, filled, stats)


def fill_from_background(disp: F32, holes: NDArray[np.bool_]) -> F32:
    """Holes (inside the subject) take the farther (smaller) of the nearest valid disparities left and right
    on their row: an occluded point belongs to the background side of the edge."""
    out = disp.copy()
    h, w = disp.shape
    valid = np.isfinite(disp) & ~holes
    idx = np.where(valid, np.arange(w)[None, :], -1)
    left = np.maximum.accumulate(idx, axis=1)
    idx_r = np.where(valid, np.arange(w)[None, :], w)
    right = np.minimum.accumulate(idx_r[:, ::-1], axis=1)[:, ::-1]
    rows = np.arange(h)[:, None]
    lv = np.where(left >= 0, disp[rows, np.clip(left, 0, w - 1)], np.inf)
    rv = np.where(right < w, disp[rows, np.clip(right, 0, w - 1)], np.inf)
    fill = np.minimum(lv, rv)
    out[holes] = fill[holes]
    return out


def cross_check(a: DepthResult, b: DepthResult, rel: tuple[float, float], tol: float = 1.0) -> NDArray[np.bool_]:
    """Pixels of ``a`` whose disparity disagrees with ``b``'s at the same point (b at offset ``rel`` from a)."""
    h, w = a.disparity.shape
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
    d = np.where(np.isfinite(a.disparity), a.disparity, 0).astype(np.float32)
    mx, my = gx - d * np.float32(rel[0]), gy - d * np.float32(rel[1])
    db = np.where(np.isfinite(b.disparity), b.disparity, -1e6).astype(np.float32)
    seen = cv2.remap(db, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=-1e6)
    return np.asarray(np.isfinite(a.disparity) & (seen > -1e5) & (np.abs(seen - a.disparity) > tol))
