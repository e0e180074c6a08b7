"""Temporal stability of depth over a take: a still surface keeps its depth from one frame set to the next.

The pipeline (one ``Temporal`` per run of consecutive frame sets, reset at the start of every chunk the farm
hands out) calls, per frame set:

    for cam in cameras:
        result = estimate(...)                              # this frame set's estimate, as today
        result = temporal.stabilise(grid, cam, result, d_range)
    ... cross-check, write ...
    temporal.advance(grid, results)                         # the frame set's final results become "previous"

A single-frame estimate turns sensor noise into depth noise: on a scene that does not move, the disparity of
a pixel changes by a fraction of a pixel every frame, which a headset shows as shimmer. As MPEG's immersive
video depth estimator does, the previous frame set's depth is used where the colour of every view that sees
a pixel did not change beyond the noise (``temporal_change.py``: the noise measured from the frames
themselves, per camera). There:

* **blended**: the new estimate agrees with the previous depth (within ``agree_sigmas`` of the estimator's own
  frame-to-frame spread, measured on those pixels, and at least ``agree_floor_px``): the output is the running
  mean of the estimates since the pixel last changed, over at most ``max_frames`` frames. A still pixel's depth
  then settles instead of shimmering, and a first frame's small error is averaged away, not frozen;
* **kept** or **replaced**: they disagree (one of the two is a mismatch). The matching cost of both on the
  current views decides: the new estimate replaces the previous one (and the mean starts again from it) only
  when its cost is clearly lower (by ``better_share``); otherwise the previous depth stays.

Everywhere else (the colour changed in some view that sees the pixel, or there was no previous depth) the new
estimate stands (**new**), unless it lies within the agreement of the previous depth and the previous depth
matches the current views clearly better (**held**): a larger jump, where an edge moved, always takes the new
estimate, so a moving edge is not dragged. ``result.stats`` records the shares. The same frames in the same
order give the same bytes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.cost import SweepLevel
from rigctl.depth.estimate import DepthResult
from rigctl.depth.grid import Grid
from rigctl.depth.packed import Packed, PackedField
from rigctl.depth.temporal_change import (
    MAD_TO_SIGMA,
    FrameChange,
    HalfPictures,
    NoiseHistory,
    frame_change,
    still_in_every_view,
)
from rigctl.errors import ParameterError

F32 = NDArray[np.float32]
COST_BAND_ROWS = 128  # rows of the pixels whose costs decide, matched at a time (see Temporal._costs)
COUNT = np.uint8  # frames in a pixel's running mean (at most max_frames): a byte a pixel and camera, kept twice


@dataclass(frozen=True)
class TemporalParams:
    enabled: bool = True
    window: int = 5  # colour-change statistic: window over which the squared frame difference is averaged, px
    change_sigmas: float = 6.0  # a pixel changed when its statistic lies this many noise spreads above the noise
    max_frames: int = 16  # the running mean of a still pixel spans at most this many frames
    agree_sigmas: float = 5.0  # new and previous depth agree within this many of the estimator's spreads ...
    agree_floor_px: float = 0.5  # ... and at least this (an estimator with a 1/16 px step has a spread of 0)
    better_share: float = 0.1  # a new estimate replaces a disagreeing previous one when its cost is this much lower
    cost_window: int = 7  # the matching cost that decides: window, px ...
    cost_keep: float = 0.5  # ... and share of the views kept per pixel (the best ones: occlusion-aware)
    hold_changed: bool = True  # changed pixels: the previous depth stays (within the agreement) if it matches better

    def __post_init__(self) -> None:
        if not 1 <= self.max_frames <= np.iinfo(COUNT).max:
            raise ParameterError(f"temporal max_frames must be 1 to {np.iinfo(COUNT).max}, got {self.max_frames}")


@dataclass
class Previous:
    """What the next frame set reads of this one: its pictures at half size (the change test's, which lets go
    of each as it reads it), each camera's final disparity and the frames in each pixel's mean. Not the frame
    set itself, nor the rest of its results (at 3840x2160 that held 16 bytes a pixel and camera more, about
    1.1 GiB for nine cameras, through the next frame set's depth; issue 24: a chunk's memory)."""

    shape: tuple[int, int]
    pictures: HalfPictures
    disparity: dict[str, Packed]  # as the results held it (``packed.py``), not a copy
    frames: dict[str, NDArray[np.uint8]] = field(default_factory=dict)  # per camera: frames in each pixel's mean


class Temporal:
    """The state carried from one frame set to the next within a run of consecutive frame sets."""

    def __init__(self, params: TemporalParams | None = None) -> None:
        self.params = params or TemporalParams()
        self.previous: Previous | None = None
        self.noise: dict[str, NoiseHistory] = {}
        self._change: tuple[Grid, FrameChange] | None = None
        self._frames: dict[str, NDArray[np.uint8]] = {}

    def reset(self) -> None:
        self.previous = None
        self.noise = {}
        self._change = None
        self._frames = {}

    def stabilise(self, grid: Grid, ref: str, result: DepthResult, d_range: tuple[float, float]) -> DepthResult:
        t0 = time.perf_counter()
        p = self.params
        d_new = result.disparity
        prev = self.previous
        if not p.enabled or prev is None or ref not in prev.disparity or prev.shape != grid.shape:
            self._frames[ref] = np.isfinite(d_new).astype(COUNT)
            return result
        change = self._frame_change(prev.pictures, grid)
        d_prev = prev.disparity[ref].plane()
        n_prev = prev.frames.get(ref)
        if n_prev is None:
            n_prev = np.isfinite(d_prev).astype(COUNT)
        still = still_in_every_view(change, grid, ref, d_prev) & np.isfinite(d_new)
        with np.errstate(invalid="ignore"):
            delta = np.where(still, d_new - d_prev, 0.0).astype(np.float32)
        spread = MAD_TO_SIGMA * float(np.median(np.abs(delta[still]))) if still.any() else 0.0
        tol = max(p.agree_floor_px, p.agree_sigmas * spread)
        agree = still & (np.abs(delta) <= tol)
        disagree = still & ~agree
        # where the colour changed in a view, the new estimate stands unless it lies within the agreement of the
        # previous depth and the previous depth matches the current views clearly better. Not beyond it: a larger
        # jump is where an edge moved, and a cost window that straddles the edge favours the old side of it (a
        # card's trailing edge was held over the strip it uncovered)
        with np.errstate(invalid="ignore"):
            changed = np.isfinite(d_new) & np.isfinite(d_prev) & ~still & (np.abs(d_new - d_prev) <= tol)
        decide = disagree | (changed if p.hold_changed else np.zeros_like(changed))
        new_better = np.zeros(d_new.shape, bool)
        prev_better = np.zeros(d_new.shape, bool)
        if decide.any():
            c_new, c_prev = self._costs(grid, ref, d_new, d_prev, decide)
            new_better[decide] = c_new < c_prev * (1.0 - p.better_share)
            prev_better[decide] = c_prev < c_new * (1.0 - p.better_share)
        kept = disagree & ~new_better
        held = changed & prev_better

        n = np.maximum(n_prev, 1).astype(np.float32)
        out = d_new.copy()
        out[agree] = (d_prev + delta / (n + 1.0))[agree]
        out[kept | held] = d_prev[kept | held]
        frames = np.isfinite(out).astype(COUNT)  # a new estimate starts a new mean
        frames[agree] = np.minimum(n_prev[agree] + 1, p.max_frames)
        frames[kept] = n_prev[kept]
        self._frames[ref] = frames

        estimated = max(1, int(np.isfinite(d_new).sum()))
        result.disparity = out
        st = result.stats
        st["temporal_blended_share"] = float(agree.sum() / estimated)
        st["temporal_kept_share"] = float(kept.sum() / estimated)
        st["temporal_replaced_share"] = float((disagree & new_better).sum() / estimated)
        st["temporal_held_share"] = float(held.sum() / estimated)
        st["temporal_new_share"] = float((np.isfinite(d_new) & ~still & ~held).sum() / estimated)
        st["temporal_agree_px"] = tol
        st["temporal_noise_sigma"] = change.sigma[ref]
        st["temporal_changed_share"] = change.share[ref]
        st["temporal_s"] = time.perf_counter() - t0
        return result

    def advance(self, grid: Grid, results: dict[str, DepthResult]) -> None:
        if not self.params.enabled:
            self.previous = None
            return
        frames = {n: self._frames[n] for n in results if n in self._frames}
        # made again, not kept from the change test: held through the depth they were 0.22 GiB at 3840x2160
        pictures = HalfPictures.of(grid).made()
        disparity = {n: PackedField.held(r, "disparity") for n, r in results.items()}
        self.previous = Previous(grid.shape, pictures, disparity, frames)
        self._frames = {}
        self._change = None

    def _frame_change(self, prev: HalfPictures, grid: Grid) -> FrameChange:
        """The colour change of every camera between the previous frame set and this one, once per frame set
        (it lets go of the previous frame set's pictures as it reads them)."""
        if self._change is None or self._change[0] is not grid:
            p = self.params
            self._change = (grid, frame_change(prev, grid, self.noise, p.window, p.change_sigmas))
        return self._change[1]

    def _costs(self, grid: Grid, ref: str, d_new: F32, d_prev: F32, where: NDArray[np.bool_]) -> tuple[F32, F32]:
        """At the pixels of ``where``: the matching cost of the new and of the previous disparity on the current
        views (the plane sweep's cost, ``cost.py``: the best views per pixel, so an occluded view drops out).

        In bands of ``COST_BAND_ROWS`` rows of ``where``, each with the cost window's rows around it, and each
        view's normalised picture only where the band's candidates reach (``SweepLevel``'s ``reach``). Whole,
        this held every view's normalised frame: 3.23 GiB, a chunk's peak at 3840x2160 (issue 24). A pixel's
        cost reads its window alone, the same samples either way (``tests/unit/test_temporal.py``)."""
        p = self.params
        views = [n for n in grid.names if n != ref and grid.offsets[n] != grid.offsets[ref]]
        ys, xs = np.nonzero(where)
        c_new, c_prev = np.zeros(ys.size, np.float32), np.zeros(ys.size, np.float32)
        if not views or not ys.size:
            return c_new, c_prev
        h, w = d_new.shape
        r = p.cost_window
        keep = max(1, math.ceil(p.cost_keep * len(views)))
        done = 0
        for b0 in range(int(ys.min()), int(ys.max()) + 1, COST_BAND_ROWS):
            b1 = b0 + COST_BAND_ROWS
            lo, hi = np.searchsorted(ys, (b0, b1))
            if lo == hi:
                continue
            band_x = xs[lo:hi]
            y0, y1 = max(0, int(ys[lo]) - r), min(h, int(ys[hi - 1]) + r + 1)
            x0, x1 = max(0, int(band_x.min()) - r), min(w, int(band_x.max()) + r + 1)
            asked = np.zeros((y1 - y0, x1 - x0), bool)  # this band's pixels alone, not the rows around it
            asked[ys[lo:hi] - y0, band_x - x0] = True
            a, b = d_new[y0:y1, x0:x1], d_prev[y0:y1, x0:x1]
            # the cost window reaches neighbours without an estimate: each candidate there takes the other's value
            a_f = np.where(np.isfinite(a), a, np.where(np.isfinite(b), b, 0.0)).astype(np.float32)
            b_f = np.where(np.isfinite(b), b, a_f).astype(np.float32)
            read = np.asarray(cv2.dilate(asked.astype(np.uint8), np.ones((r, r), np.uint8)), bool)
            reach = (float(min(a_f[read].min(), b_f[read].min())), float(max(a_f[read].max(), b_f[read].max())))
            level = SweepLevel(grid, ref, views, 1.0, (y0, y1, x0, x1), reach)
            costs = level.costs_where([a_f, b_f], asked, r, keep)
            c_new[done : done + hi - lo], c_prev[done : done + hi - lo] = costs[0], costs[1]
            done += hi - lo
        return c_new, c_prev
