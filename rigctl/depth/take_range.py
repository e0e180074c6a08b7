"""The disparity range of a take, decided once: from the plan when there is one (``--near/--far`` through the
planner, a given range, a grid folder's ``disparity_range_px``), otherwise measured once from feature matches
over a few frame sets spread across the take (:func:`rigctl.depth.measured_range.measured_range`), and
failing that the whole plausible range. A measured range is only ever widened, never narrowed: when a frame
set's estimates pile up at one of its bounds (:func:`bound_side_hits`), the pipeline widens that side and
runs the frame set again, so no frame keeps a clipped result. Hits a widening did not halve are spurious matches at
whatever bound there is, not a clipped scene: from then on that side is widened again only when more than
twice as many hit it. A planned range is the user's word and is kept; its bound hits are reported.

Every chunk of a take starts from the same :class:`SearchState` (the range and those spurious-hit thresholds).
When a chunk widened, the take's state becomes the hull of every chunk's end state (:func:`hull`, whatever the
order the chunks finished in) and every chunk is run again from it, round after round, until no chunk widens:
every published frame set then searched the same range, the widest any frame set needed."""

from __future__ import annotations

import logging
import math

import numpy as np
from pydantic import BaseModel, ConfigDict

from rigctl.depth.estimate import DepthResult
from rigctl.depth.grid import Grid, SkippedFrameSet
from rigctl.depth.measured_range import measured_range
from rigctl.depth.options import DepthOptions
from rigctl.depth.sources import FrameSource
from rigctl.keying import Keyer
from rigctl.planning.planner import search_range_px

log = logging.getLogger(__name__)

SAMPLES = 3  # frame sets the range is measured on: the first, the last and the middle one
HIT_MIN_PX = 50  # a bound is hit when more pixels than this of one camera lie at it ...
HIT_SHARE = 0.002  # ... and more than this share of that camera's estimated pixels
WIDEN_MIN_PX = 4.0  # a widening adds at least this much to the side hit ...
WIDEN_SHARE = 0.25  # ... or this share of the range's span, whichever is more
MAX_WIDEN = 3  # widenings of one frame set at most (each runs it again)
MAX_ROUNDS = 4  # runs of a take's chunks at most: the first, and each after the take's range was widened


class Widening(BaseModel):
    model_config = ConfigDict(extra="forbid")

    frame: int
    before: tuple[float, float]
    after: tuple[float, float]
    low_hits: int
    high_hits: int


class RangeDecision(BaseModel):
    """The take's range, where it came from and the frame sets it was measured on (recorded in report.json
    and in the farm's ledger, so every chunk starts from the same range)."""

    model_config = ConfigDict(extra="forbid")

    disparity_range_px: tuple[float, float]
    source: str
    planned: bool  # from a plan: kept as it is, never widened
    sampled_frames: list[int] = []

    def start(self) -> SearchState:
        return SearchState(disparity_range_px=self.disparity_range_px)


class SearchState(BaseModel):
    """What every chunk of a take starts from: the range, and per side (low, high) the bound hits a widening did
    not remove (spurious matches: only more than twice as many widen that side again)."""

    model_config = ConfigDict(extra="forbid")

    disparity_range_px: tuple[float, float]
    spurious_hits: tuple[int, int] = (0, 0)


def hull(states: list[SearchState]) -> SearchState:
    """The state wide enough for every one of ``states``: the widest range, the largest spurious thresholds
    (independent of their order, so of the order in which a farm's chunks finish)."""
    return SearchState(
        disparity_range_px=(min(s.disparity_range_px[0] for s in states), max(s.disparity_range_px[1] for s in states)),
        spurious_hits=(max(s.spurious_hits[0] for s in states), max(s.spurious_hits[1] for s in states)),
    )


class SearchRounds(BaseModel):
    """How the take's range settled (``report.json`` and ``process.json``): the state the published frame sets
    were computed from, the rounds run (1: no chunk widened the take's range), whether the last round widened
    nothing (only false when :data:`MAX_ROUNDS` ran out), and the widenings that moved the take's range."""

    model_config = ConfigDict(extra="forbid")

    state: SearchState
    rounds: int = 1
    settled: bool = True
    widenings: list[Widening] = []


def unplanned_range(width: int) -> tuple[float, float]:
    """The whole plausible range of an image ``width`` pixels wide: 0 to a quarter of the width."""
    return 0.0, float(width) / 4


def spread(numbers: list[int], count: int = SAMPLES) -> list[int]:
    """Up to ``count`` of ``numbers`` spread evenly from the first to the last."""
    if len(numbers) <= count:
        return list(numbers)
    picks = np.linspace(0, len(numbers) - 1, count).round().astype(int)
    return [numbers[i] for i in dict.fromkeys(picks.tolist())]


def decide_range(source: FrameSource, opt: DepthOptions) -> RangeDecision:
    """The take's range (see the module): one feature-matching pass over a sample of the take's frame sets
    when there is no plan. The sample is spread over every complete frame set of the take, whichever frame
    sets a run is asked for, so two runs over parts of one take search the same range."""
    if opt.disparity_range is not None:
        lo, hi = (float(v) for v in opt.disparity_range)
        return RangeDecision(disparity_range_px=(lo, hi), source="given disparity range", planned=True)
    if opt.near_m is not None:
        far = opt.far_m if opt.far_m is not None else math.inf
        rng = search_range_px(source.focal_px, source.spacing, opt.near_m, far, opt.margin_px, source.doffs)
        return RangeDecision(
            disparity_range_px=rng, source=f"planned from near {opt.near_m} m, far {far} m", planned=True
        )
    if source.disparity_range is not None:
        lo, hi = source.disparity_range
        return RangeDecision(disparity_range_px=(lo, hi), source="grid.yaml disparity_range_px", planned=True)
    grids: list[Grid] = []
    sampled: list[int] = []
    numbers = source.frame_numbers()
    for n in spread(numbers):
        try:
            grids.append(source.grid(n))
            sampled.append(n)
        except SkippedFrameSet:
            continue
    if not grids:  # every sampled frame set damaged: the first readable one
        for n in numbers:
            try:
                grids.append(source.grid(n))
                sampled.append(n)
                break
            except SkippedFrameSet:
                continue
    # in front of a green screen nothing is at infinity (zero-disparity features are fixed to the sensor)
    screen = opt.key and bool(grids) and Keyer().screen_excess(grids[0].images[grids[0].names[0]]) > 0
    measured = measured_range(grids, screen) if grids else None
    if measured is not None:
        return RangeDecision(
            disparity_range_px=measured,
            source=f"no plan: measured once from feature matches in frame sets {', '.join(map(str, sampled))}",
            planned=False,
            sampled_frames=sampled,
        )
    width = grids[0].shape[1] if grids else 0
    return RangeDecision(
        disparity_range_px=unplanned_range(width), source="no plan: the whole plausible range", planned=False,
        sampled_frames=sampled,
    )  # fmt: skip


def bound_side_hits(results: dict[str, DepthResult], d_range: tuple[float, float]) -> tuple[int, int]:
    """Pixels at the low and at the high bound, summed over the cameras whose hits count (more than
    :data:`HIT_MIN_PX` and :data:`HIT_SHARE` of their estimates at that side); (0, 0) when none does."""
    mid = (d_range[0] + d_range[1]) / 2
    low = high = 0
    for res in results.values():
        disparity, bound_hit = res.disparity, res.bound_hit  # each read makes the plane (held packed)
        estimated = int(np.isfinite(disparity).sum())
        need = max(HIT_MIN_PX, HIT_SHARE * estimated)
        with np.errstate(invalid="ignore"):
            lo_n = int((bound_hit & (disparity < mid)).sum())
            hi_n = int((bound_hit & (disparity >= mid)).sum())
        low += lo_n if lo_n > need else 0
        high += hi_n if hi_n > need else 0
    return low, high


def widened(d_range: tuple[float, float], low: bool, high: bool) -> tuple[float, float]:
    lo, hi = d_range
    step = max(WIDEN_MIN_PX, WIDEN_SHARE * (hi - lo))
    return (lo - step if low else lo), (hi + step if high else hi)
