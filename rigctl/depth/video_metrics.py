"""How depth behaves over time: the figures a headset shows as shimmer.

Fed one frame set after another (one camera's disparity, and its truth when the take has one),
:class:`VideoMetrics` measures the frame-to-frame change of the estimate:

* **static flicker**: on pixels whose true disparity did not change between the two frames (with no truth,
  on a scene known to be still, every pixel), the change of the estimate: its mean, its 99th percentile and
  the share above 0.5 px. Nothing moved there, so every bit of it is noise turned into depth noise;
* **change error**: on every pixel with a truth in both frames, the error of the estimate's change against
  the truth's change, |(d_t - d_t-1) - (g_t - g_t-1)| (mean and 99th percentile): on a moving scene this is
  what a stabiliser must keep low without dragging moving edges;
* **coverage flicker**: the share of those pixels whose estimate appears or disappears between the frames.

Only pixels estimated in both frames enter the change figures (a missing estimate has no value to change);
the coverage figure counts the others. Nothing is ever NaN: a figure with no pixel to measure is None.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict

F32 = NDArray[np.float32]

STILL_PX = 0.01  # a true disparity that changed by less than this did not move
FLICKER_PX = 0.5  # the change the issue counts as visible shimmer


class VideoScores(BaseModel):
    """Per take (one camera): the flicker and change-error figures over every pair of consecutive frames."""

    model_config = ConfigDict(extra="forbid")

    frames: int
    pairs: int
    static_pixels: int  # pixel-pairs measured for the static flicker
    static_change_mean_px: float | None
    static_change_p99_px: float | None
    static_change_over_0_5_pct: float | None
    changing_pixels: int  # pixel-pairs with a truth in both frames (0 without a truth)
    change_error_mean_px: float | None
    change_error_p99_px: float | None
    coverage_change_pct: float | None


class PairScores(BaseModel):
    """Two consecutive frames: the mean static change and the mean change error (None: nothing to measure)."""

    static_change_mean_px: float | None
    change_error_mean_px: float | None


def _mean(v: NDArray[np.float64]) -> float | None:
    return float(v.mean()) if v.size else None


def _p99(v: NDArray[np.float64]) -> float | None:
    return float(np.percentile(v, 99)) if v.size else None


class VideoMetrics:
    """Accumulates one camera's disparities frame by frame (``add``) and gives :class:`VideoScores`.

    ``static_scene``: with no truth, treat every pixel as still (a take recorded with ``motion=false``);
    without it and without a truth there is no pixel known to be still and the static figures stay None."""

    def __init__(self, static_scene: bool = False) -> None:
        self.static_scene = static_scene
        self.frames = 0
        self._prev: tuple[F32, F32 | None] | None = None
        self._static: list[NDArray[np.float64]] = []
        self._error: list[NDArray[np.float64]] = []
        self._coverage = [0, 0]  # pixels whose estimate appeared or vanished, pixels looked at
        self.per_pair: list[PairScores] = []  # one per pair of consecutive frames, in order

    def add(self, disparity: F32, truth: F32 | None = None) -> None:
        if self._prev is not None:
            self._pair(*self._prev, disparity, truth)
        self._prev = (disparity, truth)
        self.frames += 1

    def _pair(self, d0: F32, g0: F32 | None, d1: F32, g1: F32 | None) -> None:
        if d0.shape != d1.shape:
            raise ValueError(f"disparities of consecutive frames differ in size: {d0.shape} and {d1.shape}")
        e0, e1 = np.isfinite(d0), np.isfinite(d1)
        both = e0 & e1
        with np.errstate(invalid="ignore"):
            change = np.where(both, d1.astype(np.float64) - d0, 0.0)
        if g0 is not None and g1 is not None:
            known = np.isfinite(g0) & np.isfinite(g1)
            with np.errstate(invalid="ignore"):
                true_change = np.where(known, g1.astype(np.float64) - g0, 0.0)
            still = known & (np.abs(true_change) < STILL_PX)
            error = np.abs(change - true_change)[known & both]
            self._error.append(error)
        elif self.static_scene:
            still = e0 | e1
            known = still
            error = np.zeros(0)
        else:
            self.per_pair.append(PairScores(static_change_mean_px=None, change_error_mean_px=None))
            return
        static = np.abs(change[still & both])
        self._static.append(static)
        self.per_pair.append(PairScores(static_change_mean_px=_mean(static), change_error_mean_px=_mean(error)))
        self._coverage[0] += int((known & (e0 != e1)).sum())
        self._coverage[1] += int(known.sum())

    def scores(self) -> VideoScores:
        static = np.concatenate(self._static) if self._static else np.zeros(0)
        error = np.concatenate(self._error) if self._error else np.zeros(0)
        seen, total = self._coverage
        return VideoScores(
            frames=self.frames,
            pairs=max(0, self.frames - 1),
            static_pixels=int(static.size),
            static_change_mean_px=_mean(static),
            static_change_p99_px=_p99(static),
            static_change_over_0_5_pct=float(np.mean(static > FLICKER_PX) * 100) if static.size else None,
            changing_pixels=int(error.size),
            change_error_mean_px=_mean(error),
            change_error_p99_px=_p99(error),
            coverage_change_pct=100.0 * seen / total if total else None,
        )
