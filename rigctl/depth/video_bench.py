"""``rigctl bench depth --video``: depth over time on simulated takes with exact truth, temporal stabilisation
on and off side by side. Per frame: bad 1.0 / 2.0, missed and false foreground, the mean frame-to-frame change
where the truth did not move, the seconds; per take (:mod:`rigctl.depth.video_metrics`): the static flicker
(mean, p99, share above 0.5 px), the error of the frame-to-frame change against the truth's change, and the
time per frame. The takes come from the caller (``rigctl.simulated_presenter.presenter_video``: a still and
a moving realistic presenter, rectified with their true calibration) as frame sources; each frame set goes
through the take-level pipeline exactly as ``rigctl depth`` runs it, without writing outputs."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rigctl.depth.metrics import score
from rigctl.depth.video_metrics import VideoMetrics, VideoScores
from rigctl.publish import publish_figure


@dataclass
class VideoTake:
    """A frame source with truth (``ArrayTake``), whether its scene is still, and the camera to score."""

    name: str
    source: Any
    still: bool
    camera: str = "r1c1"


@dataclass
class FrameRow:
    frame: int
    seconds: float
    bad_1: float
    bad_2: float
    missed_fg_pct: float  # truth pixels with no estimate
    false_fg_pct: float  # estimated pixels where the truth has no subject
    static_change_mean_px: float | None  # against the previous frame (None for the first)
    change_error_mean_px: float | None
    disparity_range_px: tuple[float, float]

    def to_json(self) -> dict[str, object]:
        return dict(self.__dict__, disparity_range_px=list(self.disparity_range_px))


@dataclass
class VideoRun:
    take: str
    temporal: bool
    frames: list[FrameRow] = field(default_factory=list)
    scores: VideoScores | None = None

    @property
    def seconds_per_frame(self) -> float:
        return float(np.mean([f.seconds for f in self.frames])) if self.frames else 0.0

    @property
    def bad_1(self) -> float:
        return float(np.mean([f.bad_1 for f in self.frames])) if self.frames else 0.0

    def to_json(self) -> dict[str, object]:
        return {
            "take": self.take,
            "temporal": self.temporal,
            "seconds_per_frame": self.seconds_per_frame,
            "bad_1.0_mean": self.bad_1,
            "scores": self.scores.model_dump() if self.scores else None,
            "frames": [f.to_json() for f in self.frames],
        }


def frame_row(frame: int, seconds: float, disparity: Any, truth: Any, d_range: tuple[float, float]) -> FrameRow:
    mask = np.isfinite(truth)
    sc = score(disparity, truth, mask)
    est = np.isfinite(disparity)
    false_fg = float((est & ~mask).sum() / max(1, est.sum()) * 100)
    return FrameRow(
        frame,
        seconds,
        float(sc["bad_1.0"] or 0.0),
        float(sc["bad_2.0"] or 0.0),
        float(sc["no_estimate_pct"] or 0.0),
        false_fg,
        None,
        None,
        (float(d_range[0]), float(d_range[1])),
    )


def run_take(
    take: VideoTake, temporal: bool, preset: str = "best", progress: Callable[[str], None] | None = None
) -> VideoRun:
    """Every frame set of ``take`` through the pipeline, one camera, no outputs written."""
    from rigctl.depth.pipeline import TakeProcessor
    from rigctl.depth.run import DepthOptions

    opt = DepthOptions(preset=preset, cameras=(take.camera,), temporal=temporal, chunk=len(take.source.frame_numbers()))
    run = VideoRun(take.name, temporal)
    metrics = VideoMetrics(static_scene=take.still)
    processor = TakeProcessor(take.source, opt)
    for n in take.source.frame_numbers():
        if progress:
            progress(f"{take.name}, temporal {'on' if temporal else 'off'}: frame {n}")
        t0 = time.perf_counter()
        done = processor.process(n)
        seconds = time.perf_counter() - t0
        truth = done.grid.truth[take.camera] if done.grid.truth else None
        assert truth is not None, "a video bench take carries its truth"
        disparity = done.results[take.camera].disparity
        metrics.add(disparity, truth)
        row = frame_row(n, seconds, disparity, truth, done.report.disparity_range_px)
        if metrics.per_pair and metrics.frames > 1:
            row.static_change_mean_px = metrics.per_pair[-1].static_change_mean_px
            row.change_error_mean_px = metrics.per_pair[-1].change_error_mean_px
        run.frames.append(row)
    run.scores = metrics.scores()
    return run


@dataclass
class VideoBenchResult:
    runs: list[VideoRun]

    def to_json(self) -> dict[str, object]:
        return {"runs": [r.to_json() for r in self.runs]}


def run_video_bench(
    takes: list[VideoTake], preset: str = "best", progress: Callable[[int, int, str], None] | None = None
) -> VideoBenchResult:
    """Each take with temporal stabilisation off, then on."""
    runs = []
    total = sum(len(t.source.frame_numbers()) for t in takes) * 2
    k = 0

    def step(label: str) -> None:
        nonlocal k
        if progress:
            progress(k, total, label)
        k += 1

    for take in takes:
        for temporal in (False, True):
            runs.append(run_take(take, temporal, preset, step))
    if progress:
        progress(total, total, "done")
    return VideoBenchResult(runs)


def _fmt(v: float | None, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def format_video_table(result: VideoBenchResult) -> str:
    lines = [
        "take       temporal  bad1.0  missed fg %  false fg %  flicker mean  p99    >0.5px %  change err mean  "
        "p99    coverage chg %  s/frame"
    ]
    for r in result.runs:
        s = r.scores
        assert s is not None
        missed = float(np.mean([f.missed_fg_pct for f in r.frames])) if r.frames else 0.0
        false = float(np.mean([f.false_fg_pct for f in r.frames])) if r.frames else 0.0
        lines.append(
            f"{r.take:<10} {'on ' if r.temporal else 'off'}       {r.bad_1:6.2f}  {missed:11.2f}  {false:10.2f}  "
            f"{_fmt(s.static_change_mean_px):>12}  {_fmt(s.static_change_p99_px):>5}  "
            f"{_fmt(s.static_change_over_0_5_pct, 2):>8}  {_fmt(s.change_error_mean_px):>15}  "
            f"{_fmt(s.change_error_p99_px):>5}  {_fmt(s.coverage_change_pct, 2):>14}  {r.seconds_per_frame:7.2f}"
        )
    lines.append(
        "per frame, averaged: bad 1.0, missed foreground (truth without estimate), false foreground (estimate "
        "without truth), %; over time: flicker = frame-to-frame change where the truth did not move, change err = "
        "error of the change against the truth's change (px); --json has every frame"
    )
    return "\n".join(lines)


def plot_video(result: VideoBenchResult, path: Path) -> Path:
    """Per take: bad 1.0 and the static change frame by frame (temporal off dashed, on solid), and the
    flicker against the time per frame (like the error-against-time plot)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    takes = list(dict.fromkeys(r.take for r in result.runs))
    fig, axes = plt.subplots(len(takes), 3, figsize=(13, 3.4 * len(takes)), squeeze=False)
    for row, name in zip(axes, takes, strict=True):
        for r in (r for r in result.runs if r.take == name):
            style = "-" if r.temporal else "--"
            label = f"temporal {'on' if r.temporal else 'off'}"
            xs = [f.frame for f in r.frames]
            row[0].plot(xs, [f.bad_1 for f in r.frames], style, label=label)
            pairs = [(f.frame, f.static_change_mean_px) for f in r.frames if f.static_change_mean_px is not None]
            row[1].plot([p[0] for p in pairs], [p[1] for p in pairs], style, marker=".", label=f"still, {label}")
            errs = [(f.frame, f.change_error_mean_px) for f in r.frames if f.change_error_mean_px is not None]
            if errs and not all(f.static_change_mean_px == f.change_error_mean_px for f in r.frames):
                xs_e, ys_e = [e[0] for e in errs], [e[1] for e in errs]
                row[1].plot(xs_e, ys_e, style, marker="x", label=f"change error, {label}")
            assert r.scores is not None
            y = r.scores.static_change_mean_px
            if y is not None:
                row[2].scatter(r.seconds_per_frame, y, marker="o" if r.temporal else "s", label=label)
        row[0].set_title(f"{name}: bad 1.0 px (%) per frame", fontsize=9)
        row[1].set_title(f"{name}: frame-to-frame change (px)", fontsize=9)
        row[2].set_title(f"{name}: flicker against time", fontsize=9)
        row[2].set_xlabel("seconds per frame (one camera)")
        for ax in row:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        row[0].set_xlabel("frame")
        row[1].set_xlabel("frame")
    fig.tight_layout()
    publish_figure(path, fig, 80)  # whole or absent, never a cut PNG
    plt.close(fig)
    return path
