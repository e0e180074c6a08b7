"""``rigctl depth``: a take or grid folder through the take-level pipeline (:mod:`rigctl.depth.pipeline`),
per camera and frame: disparity + depth as EXR (NUKE layers), PFM, a colour-mapped PNG preview (red near,
blue far), and ``report.json`` (:class:`rigctl.depth.report.TakeReport`: the take's range and where it came
from, per frame set the range searched, timings per stage, keyed share, levels left out, bound hits; per take
the bound hits summed and, when the take has a truth, the flicker figures of every camera)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from rigctl.depth.estimate import DepthResult
from rigctl.depth.export import DEFAULT_FORMATS, Exporter, Target, check_room, colour_preview, write_outputs
from rigctl.depth.grid import Grid, TakeGrid
from rigctl.depth.options import DEFAULT_CHUNK, DepthOptions
from rigctl.depth.pipeline import ChunkEnd, FrameDone, TakeProcessor, chunks, settle
from rigctl.depth.report import TakeReport
from rigctl.depth.sources import FrameSource, OneGrid, frame_size, open_source
from rigctl.depth.take_range import SearchState, unplanned_range
from rigctl.depth.video_metrics import VideoMetrics
from rigctl.errors import ParameterError
from rigctl.exr import to_colour
from rigctl.layout import check_layout
from rigctl.take.framesets import check_frames

__all__ = [
    "DEFAULT_CHUNK",
    "DepthOptions",
    "Target",
    "colour_preview",
    "depth_grid",
    "run_depth",
    "select_frames",
    "unplanned_range",
    "write_outputs",
]


def depth_grid(grid: Grid, opt: DepthOptions) -> dict[str, DepthResult]:
    """Depth for the requested cameras of one grid on its own (a one-frame take)."""
    return TakeProcessor(OneGrid(grid), opt).depth(grid)


def select_frames(source: FrameSource, frames: Sequence[int] | None) -> list[int]:
    """The frame sets to process: those asked for (each a complete frame set), or every complete one. A grid
    folder is one frame set, 0, as ``rigctl render`` reads it: --frames asks for that one or is refused."""
    numbers = check_frames(frames, source.frame_numbers(), source.name)
    if isinstance(source, OneGrid):
        return numbers
    if not numbers:
        raise ParameterError(f"{source.name}: the take has no complete frame set")
    return numbers


class VideoScoring:
    """Each camera's flicker over the take (:mod:`rigctl.depth.video_metrics`), fed by the frames that carry a
    truth."""

    def __init__(self) -> None:
        self.metrics: dict[str, VideoMetrics] = {}

    def add(self, done: FrameDone) -> None:
        if not done.grid.truth:
            return
        for cam, res in done.results.items():
            truth = done.grid.truth.get(cam)
            if truth is not None:
                self.metrics.setdefault(cam, VideoMetrics()).add(res.disparity, truth)

    def fill(self, report: TakeReport) -> None:
        report.video = {cam: m.scores() for cam, m in self.metrics.items()}


def run_depth(
    source: Path,
    out: Path,
    opt: DepthOptions,
    frames: Sequence[int] | None = None,
    formats: tuple[str, ...] = DEFAULT_FORMATS,
    progress: Callable[[int, int, str], None] | None = None,
    skip_damaged: bool = False,
    layout: str = "frames",
    colour: str = "rec709",
) -> TakeReport:
    """Depth for a take (rectified) or a grid folder; writes outputs (in ``layout``, see rigctl.layout) and
    ``report.json``; returns the report.

    A damaged frame of a take stops it (naming file and byte) unless ``skip_damaged``: then its frame set is
    left out and the damaged frames are listed in the report's ``damaged_skipped``."""
    t_start = time.perf_counter()
    check_layout(layout)  # an unknown layout is refused before any work
    to_colour(np.zeros((1, 3), np.float32), colour)  # and an unknown colour space
    src = open_source(source, skip_damaged=skip_damaged)
    numbers = select_frames(src, frames)
    cams = [c for c in (opt.cameras or src.names) if c in src.names]  # another name is refused just below
    check_room(out, len(numbers), len(cams), frame_size(src), formats)  # before the range, the first of the work
    # a grid folder is one picture: the frames layout keeps its outputs in DIR itself, as before
    exporter = Exporter(out, layout, colour, formats, flat=src.flat and layout == "frames")
    processor = TakeProcessor(src, opt, exporter=exporter)
    report = TakeReport(
        source=str(source), preset=opt.preset, range=processor.decision, chunk=opt.chunk, warmup=opt.warmup,
        temporal=opt.temporal,
    )  # fmt: skip
    video = VideoScoring()
    position = {n: i for i, n in enumerate(numbers)}
    cams = processor.cameras
    this_round = 1

    def step(n: int, cam: str) -> None:
        if progress:
            again = f" (round {this_round}: the take's range was widened)" if this_round > 1 else ""
            total = len(numbers) * len(cams)  # cameras started of all cameras of every frame set
            progress(position[n] * len(cams) + cams.index(cam), total, f"frame {n} camera {cam}{again}")

    def run_round(state: SearchState, n: int) -> list[ChunkEnd]:
        """Every chunk from ``state``: a later round replaces every output and report of the one before."""
        nonlocal video, this_round
        this_round, video, ends = n, VideoScoring(), []
        report.frames = {}
        for chunk in chunks(numbers, opt.chunk):
            for done in processor.run_chunk(chunk, step, state=state):
                assert isinstance(done, FrameDone)  # nothing is caught: an error ends the run
                report.frames[str(done.number)] = done.report
                video.add(done)
                del done  # its pictures and results: not held through the next frame set's depth
            ends.append(processor.chunk_end())
        return ends

    report.search = settle(run_round, processor.decision.start(), processor.decision.planned)
    report.bound_hit_pixels = sum(f.bound_hit_pixels for f in report.frames.values())
    report.widenings = [w for f in report.frames.values() for w in f.widenings]
    video.fill(report)
    if isinstance(src, TakeGrid):
        report.damaged_skipped = list(src.reader.damaged)
    report.seconds = time.perf_counter() - t_start
    report.write(out / "report.json")
    if progress:
        progress(len(numbers) * len(cams), len(numbers) * len(cams), "done")
    return report
