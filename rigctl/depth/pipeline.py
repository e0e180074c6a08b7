"""The take-level pipeline: ONE object that processes a take's frame sets, used by ``rigctl depth``,
``rigctl process`` (each farm task is a chunk), ``rigctl demo`` and ``rigctl bench depth``.

Per frame set (:meth:`TakeProcessor.process`): read the grid from the :class:`~rigctl.depth.sources.
FrameSource`; key and estimate every asked camera over the take's range (decided once:
:mod:`rigctl.depth.take_range`); when the estimates pile up at a bound of a measured range, widen it and run
the frame set again; stabilise each camera over time (:class:`rigctl.depth.temporal.Temporal`);
cross-check the cameras; export (:class:`rigctl.depth.export.Exporter`); report (:class:`FrameReport`).

State carried from one frame set to the next: the range (widened, never narrowed) and the temporal
stabiliser's previous frame set. A take is processed as contiguous chunks of ``DepthOptions.chunk`` frame
sets (:func:`chunks`) that a farm hands out independently, so each chunk's outputs depend only on its frame
sets, the ``DepthOptions.warmup`` frame sets of the take before its first (processed to settle the
stabiliser, not written or reported: no temporal pop at the chunk's first frame) and the
:class:`~rigctl.depth.take_range.SearchState` it starts from. The take's rounds (:func:`settle`) make that
state the same for every chunk and wide enough for all of them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from rigctl.depth.edge import occlusion_order, ordered
from rigctl.depth.estimate import DepthResult, cross_check, estimate
from rigctl.depth.export import Exporter, FileRecord
from rigctl.depth.grid import Grid, SkippedFrameSet
from rigctl.depth.metrics import score
from rigctl.depth.options import DepthOptions
from rigctl.depth.presets import PRESETS, Preset
from rigctl.depth.report import CameraDepth, FrameReport, Timings, TruthScores
from rigctl.depth.sources import FrameSource
from rigctl.depth.take_range import (
    MAX_ROUNDS,
    MAX_WIDEN,
    RangeDecision,
    SearchRounds,
    SearchState,
    Widening,
    bound_side_hits,
    decide_range,
    hull,
    unplanned_range,
    widened,
)
from rigctl.depth.temporal import Temporal, TemporalParams
from rigctl.errors import ParameterError
from rigctl.keying import Keyer
from rigctl.timecode import Timecode

Progress = Callable[[str], None]


def chunks(numbers: list[int], size: int) -> list[list[int]]:
    """``numbers`` (in order) as runs of ``size`` consecutive frame sets, the last one shorter."""
    if size < 1:
        raise ParameterError(f"--chunk must be at least 1 frame set, got {size}")
    return [numbers[i : i + size] for i in range(0, len(numbers), size)]


@dataclass
class ChunkEnd:
    """Where a chunk's search ended (the widest state it reached) and the widenings on its way."""

    state: SearchState
    widenings: list[Widening]


def settle(run_round: Callable[[SearchState, int], list[ChunkEnd]], start: SearchState, planned: bool) -> SearchRounds:
    """Run the take's chunks (``run_round(state, round)``) from ``start``; while any chunk widened, run them all
    again from the hull of every chunk's end state (at most :data:`MAX_ROUNDS` rounds). Returns how it
    settled: then every published frame set searched that one range."""
    state = start
    moved: list[Widening] = []
    for n in range(1, MAX_ROUNDS + 1):
        ends = run_round(state, n)
        new = hull([state, *(e.state for e in ends)])
        if planned or new == state:
            return SearchRounds(state=state, rounds=n, settled=True, widenings=moved)
        # in frame order whatever order the chunks finished in (a warm-up frame's widening may appear twice)
        moved += sorted((w for e in ends for w in e.widenings), key=lambda w: (w.frame, w.before, w.after))
        if n == MAX_ROUNDS:
            return SearchRounds(state=state, rounds=n, settled=False, widenings=moved)
        state = new
    raise AssertionError("unreachable")


def _plain(value: Any) -> Any:
    """Statistics as plain JSON values (numpy scalars as Python numbers)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _rel(grid: Grid, a: str, b: str) -> tuple[float, float]:
    return grid.offsets[b][0] - grid.offsets[a][0], grid.offsets[b][1] - grid.offsets[a][1]


def order_all(grid: Grid, out: dict[str, DepthResult]) -> None:
    """No camera's depth in front of what the others see (:func:`rigctl.depth.edge.occlusion_order`): a pixel
    that most views see farther takes what they see, or no depth (then no confidence, no flags) on the screen."""
    t0 = time.perf_counter()
    order = occlusion_order(grid, {cam: res.disparity for cam, res in out.items()})
    for cam, (flagged, value) in order.items():
        res = out[cam]
        disparity = ordered(res.disparity, flagged, value)
        res.disparity = disparity
        gone = flagged & ~np.isfinite(disparity)
        if gone.any():  # the planes are held packed: each one changed is made, changed and assigned back
            res.confidence = np.where(gone, np.float32(0.0), res.confidence)
            res.unreliable = res.unreliable & ~gone
            res.bound_hit = res.bound_hit & ~gone
        res.stats["occlusion_order_pixels"] = int(flagged.sum())
        res.stats["occlusion_order_removed_pixels"] = int(gone.sum())
        res.stats["occlusion_order_s"] = (time.perf_counter() - t0) / len(out)


def cross_check_all(grid: Grid, out: dict[str, DepthResult]) -> None:
    """Each camera against its nearest computed neighbour: a point where two cameras disagree is not trusted
    (confidence 0); it is not replaced, because either camera may be the one that is wrong there."""
    for cam, res in out.items():
        t0 = time.perf_counter()
        others = [c for c in out if c != cam]
        nearest = min(others, key=lambda c: math.hypot(*_rel(grid, cam, c)))
        bad = cross_check(res, out[nearest], _rel(grid, cam, nearest)) & (res.matte > 0)
        if bad.any():
            res.confidence = np.where(bad, np.float32(0.0), res.confidence)
        res.stats["cross_check_with"] = nearest
        res.stats["cross_check_failed_pixels"] = int(bad.sum())
        res.stats["cross_check_s"] = time.perf_counter() - t0


@dataclass
class FrameDone:
    """One processed frame set: its grid and final results (for scoring), its report, the files written."""

    number: int
    grid: Grid
    results: dict[str, DepthResult]
    report: FrameReport
    files: dict[str, FileRecord]


@dataclass
class FrameFailed:
    number: int
    error: BaseException


@dataclass
class Computed:
    """A frame set whose depth is done and whose export is not: :meth:`write` exports it and times it, elapsed
    and CPU seconds. (Exporting it in a thread while the next frame set's depth runs was measured on two cores
    and not kept: -6 % to +15 % wall time, more CPU seconds; it reads only its own grid and results.)"""

    number: int
    grid: Grid
    results: dict[str, DepthResult]
    report: FrameReport
    exporter: Exporter | None
    d_range: tuple[float, float]
    timing: tuple[float | None, Timecode | None]

    def write(self) -> FrameDone:
        files: dict[str, FileRecord] = {}
        cpu = time.process_time
        t0, c0 = time.perf_counter(), cpu()
        if self.exporter is not None:
            files = self.exporter.write(self.number, self.grid, self.results, self.d_range, *self.timing)
        self.report.timings_s.write = time.perf_counter() - t0
        self.report.timings_s.write_cpu = cpu() - c0
        return FrameDone(self.number, self.grid, self.results, self.report, files)


class TakeProcessor:
    """Processes the frame sets of one source, in order, chunk by chunk (see the module)."""

    def __init__(
        self,
        source: FrameSource,
        opt: DepthOptions,
        decision: RangeDecision | None = None,
        exporter: Exporter | None = None,
    ) -> None:
        opt.check()  # what needs no take: the verbs checked it before any folder or cluster
        cameras = list(opt.cameras) if opt.cameras else list(source.names)
        unknown = [c for c in cameras if c not in source.names]
        if unknown:
            raise ParameterError(f"no camera {', '.join(unknown)} in the grid (it has {', '.join(source.names)})")
        self.source = source
        self.opt = opt
        self.preset: Preset = PRESETS[opt.preset]
        self.cameras = cameras
        self.keyer = Keyer() if opt.key else None
        self.decision = decision if decision is not None else decide_range(source, opt)
        self.exporter = exporter
        self.temporal = Temporal(TemporalParams(enabled=opt.temporal))
        self.d_range = self.decision.disparity_range_px
        self.widenings: list[Widening] = []  # every widening of the chunk, warm-up included, in order
        self._last_widenings: list[Widening] = []
        # per side, the bound hits a widening did not remove (spurious matches at whatever bound there is):
        # only more than twice as many count as the scene being clipped
        self.spurious = [0, 0]
        self._start = self._reached = self.decision.start()
        self._take_numbers: list[int] | None = None

    def state(self) -> SearchState:
        return SearchState(disparity_range_px=self.d_range, spurious_hits=(self.spurious[0], self.spurious[1]))

    def start_chunk(self, state: SearchState | None = None) -> None:
        """A new chunk: from ``state`` (the take's range as decided by default), no previous frame set."""
        self._start = self._reached = state if state is not None else self.decision.start()
        self.widenings = []
        self._restart()

    def _restart(self) -> None:
        self._reached = hull([self._reached, self.state()]) if self.widenings else self._reached
        self.d_range = self._start.disparity_range_px
        self.spurious = list(self._start.spurious_hits)
        self.temporal.reset()

    def chunk_end(self) -> ChunkEnd:
        """The widest state the chunk reached (a failed frame set's restart does not forget a widening)."""
        return ChunkEnd(hull([self._reached, self.state()]), list(self.widenings))

    def warmup_frames(self, first: int) -> list[int]:
        """The ``DepthOptions.warmup`` frame sets of the take just before ``first`` (none for the first chunk)."""
        if self.opt.warmup < 1:
            return []
        if self._take_numbers is None:
            self._take_numbers = self.source.frame_numbers()
        before = [n for n in self._take_numbers if n < first]
        return before[-self.opt.warmup :]

    def _estimate(self, grid: Grid, d_range: tuple[float, float], progress: Progress | None) -> dict[str, DepthResult]:
        out = {}
        for cam in self.cameras:
            if progress:
                progress(cam)
            out[cam] = estimate(grid, cam, d_range, self.preset, self.keyer)
        return out

    def depth(self, grid: Grid, number: int = 0, progress: Progress | None = None) -> dict[str, DepthResult]:
        """Depth of the asked cameras of one frame set, over the current range (widened and run again when a
        measured range is hit), stabilised over time and cross-checked. Advances the temporal state."""
        frame_widenings: list[Widening] = []
        results = self._estimate(grid, self.d_range, progress)
        while not self.decision.planned and len(frame_widenings) < MAX_WIDEN:
            hits = bound_side_hits(results, self.d_range)
            if frame_widenings:
                last = frame_widenings[-1]
                for side, before in enumerate((last.low_hits, last.high_hits)):
                    if before > 0 and hits[side] > before / 2:  # not halved: matches at any bound, not clipping
                        self.spurious[side] = max(self.spurious[side], hits[side])
            low, high = (h if h > 2 * self.spurious[i] else 0 for i, h in enumerate(hits))
            if not (low or high):
                break
            after = widened(self.d_range, bool(low), bool(high))
            frame_widenings.append(
                Widening(frame=number, before=self.d_range, after=after, low_hits=low, high_hits=high)
            )
            self.d_range = after
            results = self._estimate(grid, self.d_range, progress)
        self.widenings += frame_widenings
        self._last_widenings = frame_widenings
        for cam in self.cameras:
            results[cam] = self.temporal.stabilise(grid, cam, results[cam], self.d_range)
        if len(results) > 1:
            order_all(grid, results)
        if self.preset.cross_check and len(results) > 1:
            cross_check_all(grid, results)
        self.temporal.advance(grid, results)
        grid.frames.drop_made()  # the estimates' greys and 8-bit copies: the write needs none of them
        return results

    def run_chunk(
        self,
        numbers: list[int],
        progress: Callable[[int, str], None] | None = None,
        catch: tuple[type[BaseException], ...] = (),
        state: SearchState | None = None,
    ) -> Iterator[FrameDone | FrameFailed]:
        """One chunk's frame sets in order, from ``state`` (see :meth:`start_chunk`) after warming the temporal
        state up on the frame sets before it (:meth:`warmup_frames`: processed, neither written nor yielded).
        A frame set with a damaged frame (skipped by the source) is left out; an error of a type in ``catch``
        is yielded as :class:`FrameFailed` (a warm-up frame's is not) and the chunk goes on from a fresh
        state, anything else ends the run. :meth:`chunk_end` then tells where its search ended."""
        self.start_chunk(state)
        for n in self.warmup_frames(numbers[0]) if numbers else []:
            try:
                self.depth(self.source.grid(n), n)
            except SkippedFrameSet:
                continue
            except catch:
                self._restart()
        for n in numbers:
            step = None if progress is None else (lambda cam, n=n: progress(n, cam))
            try:
                yield self.process(n, step)
            except SkippedFrameSet:
                continue
            except catch as exc:
                self._restart()
                yield FrameFailed(n, exc)

    def process(self, number: int, progress: Progress | None = None) -> FrameDone:
        """One frame set, start to end: read, depth, export, report."""
        return self.computed(number, progress).write()

    def computed(self, number: int, progress: Progress | None = None) -> Computed:
        """One frame set read and its depth computed, its export still to do (:meth:`Computed.write`): what
        :meth:`process` does in two steps, for a bench that measures them apart."""
        t0 = time.perf_counter()
        grid = self.source.grid(number)
        t_load = time.perf_counter() - t0
        t0 = time.perf_counter()
        results = self.depth(grid, number, progress)
        t_depth = time.perf_counter() - t0
        if not any(np.isfinite(r.disparity).any() for r in results.values()):
            notes = sorted({str(r.stats.get("note", "no camera found a match")) for r in results.values()})
            raise ParameterError(f"{self.source.name}: frame {number}: no depth could be estimated: {'; '.join(notes)}")
        # the report is made now: the next frame set's depth changes the range and the widenings it reads
        report = self.frame_report(grid, results, Timings(load=t_load, depth=t_depth))
        timing = self.source.timing(number) if self.exporter is not None else (None, None)
        return Computed(number, grid, results, report, self.exporter, self.d_range, timing)

    def frame_report(self, grid: Grid, results: dict[str, DepthResult], timings: Timings) -> FrameReport:
        full = unplanned_range(grid.shape[1])
        per_cam: dict[str, CameraDepth] = {}
        for cam, res in results.items():
            st = CameraDepth(**_plain(dict(res.stats)))
            truth = grid.truth.get(cam) if grid.truth else None
            if truth is not None:
                st["against_truth"] = TruthScores.model_validate(score(res.disparity, truth, np.isfinite(truth)))
            per_cam[cam] = st
        lo, hi = self.d_range
        was_widened = self.d_range != self.decision.disparity_range_px
        return FrameReport(
            disparity_range_px=(float(lo), float(hi)),
            range_source=self.decision.source + (" (widened)" if was_widened else ""),
            levels_skipped_by_plan=max(0.0, (full[1] - full[0]) - (hi - lo)),
            keyed_background_share=float(np.mean([r.stats["keyed_background_share"] for r in results.values()])),
            bound_hit_pixels=int(sum(r.stats.get("bound_hit_pixels", 0) for r in results.values())),
            widenings=list(self._last_widenings),
            cameras=per_cam,
            timings_s=timings,
        )
