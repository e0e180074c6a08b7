"""Flicker and change-error figures (rigctl.depth.video_metrics) on arrays whose answer is known, and the video
bench's plumbing on a tiny in-memory take (the bench itself runs minutes: ``rigctl bench depth --video``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rigctl.depth.grid import Grid
from rigctl.depth.scenes import surfaces
from rigctl.depth.video_bench import VideoTake, format_video_table, plot_video, run_video_bench
from rigctl.depth.video_metrics import VideoMetrics
from rigctl.timecode import Timecode

INF = np.float32(np.inf)


def test_static_flicker_is_the_change_where_the_truth_did_not_move() -> None:
    truth = np.full((4, 4), 10.0, np.float32)
    m = VideoMetrics()
    m.add(np.full((4, 4), 10.0, np.float32), truth)
    m.add(np.full((4, 4), 10.2, np.float32), truth)  # every pixel moved 0.2 px: flicker
    step = np.full((4, 4), 10.2, np.float32)
    step[0, 0] = 11.0  # one pixel jumps 0.8 px: above 0.5 px
    m.add(step, truth)
    s = m.scores()
    assert s.frames == 3 and s.pairs == 2 and s.static_pixels == 32
    assert s.static_change_mean_px == pytest.approx((16 * 0.2 + 0.8) / 32, abs=1e-5)
    assert s.static_change_over_0_5_pct == pytest.approx(100 / 32)
    assert s.static_change_p99_px is not None and 0.2 < s.static_change_p99_px <= 0.8
    assert [p.static_change_mean_px for p in m.per_pair] == pytest.approx([0.2, 0.8 / 16], abs=1e-5)


def test_change_error_is_zero_when_the_estimate_follows_the_truth_and_the_lag_when_it_does_not() -> None:
    g0 = np.full((3, 3), 5.0, np.float32)
    g1 = g0 + np.float32(1.0)  # the subject came 1 px nearer everywhere
    follows, lags = VideoMetrics(), VideoMetrics()
    for m, d1 in ((follows, g1), (lags, g0)):
        m.add(g0.copy(), g0)
        m.add(d1.copy(), g1)
    assert follows.scores().change_error_mean_px == pytest.approx(0.0)
    assert lags.scores().change_error_mean_px == pytest.approx(1.0)  # kept the old depth: 1 px behind
    assert follows.scores().static_pixels == 0  # nothing was still


def test_missing_estimates_count_as_coverage_change_never_as_nan() -> None:
    truth = np.full((2, 2), 3.0, np.float32)
    d0 = np.full((2, 2), 3.0, np.float32)
    d1 = d0.copy()
    d1[0, 0] = INF  # the estimate vanished at one pixel
    m = VideoMetrics()
    m.add(d0, truth)
    m.add(d1, truth)
    s = m.scores()
    assert s.coverage_change_pct == pytest.approx(25.0)
    assert s.static_pixels == 3 and s.static_change_mean_px == 0.0
    for value in s.model_dump().values():
        assert value is None or math.isfinite(value)
    empty = VideoMetrics().scores()
    assert empty.static_change_mean_px is None and empty.change_error_p99_px is None and empty.pairs == 0


def test_a_still_scene_without_truth_measures_every_pixel_and_other_scenes_nothing() -> None:
    d0 = np.zeros((2, 2), np.float32)
    still, unknown = VideoMetrics(static_scene=True), VideoMetrics()
    for m in (still, unknown):
        m.add(d0, None)
        m.add(d0 + np.float32(0.5), None)
    assert still.scores().static_change_mean_px == pytest.approx(0.5)
    assert unknown.scores().static_pixels == 0 and unknown.scores().static_change_mean_px is None


class NoisyStill:
    """A still scene (one stratified grid) whose every frame set has fresh 8-bit-like noise."""

    flat = False
    doffs = 0.0

    def __init__(self, frames: int) -> None:
        self.base = surfaces((64, 64), 0)
        assert self.base.truth is not None
        self.names = list(self.base.names)
        self.focal_px, self.spacing = self.base.focal_px, self.base.spacing
        self.disparity_range = self.base.disparity_range
        self.frames = frames

    @property
    def name(self) -> str:
        return "noisy still"

    def frame_numbers(self) -> list[int]:
        return list(range(self.frames))

    def timing(self, number: int) -> tuple[float | None, Timecode | None]:
        return 25.0, None

    def grid(self, number: int) -> Grid:
        rng = np.random.default_rng(number)
        images = {n: np.clip(self.base.images[n] + rng.normal(0, 0.01, (64, 64, 3)), 0, 1) for n in self.names}
        return Grid(list(self.names), images, dict(self.base.offsets), self.focal_px, self.spacing,
                    disparity_range=self.disparity_range, truth=self.base.truth)  # fmt: skip


def test_video_bench_scores_each_take_with_temporal_off_and_on(tmp_path: Path) -> None:
    take = VideoTake("still", NoisyStill(3), still=True)
    result = run_video_bench([take], preset="fast")
    assert [(r.take, r.temporal) for r in result.runs] == [("still", False), ("still", True)]
    off = result.runs[0]
    assert [f.frame for f in off.frames] == [0, 1, 2] and off.frames[0].static_change_mean_px is None
    assert off.scores is not None and off.scores.pairs == 2 and off.scores.static_pixels > 0
    assert off.scores.static_change_mean_px is not None and off.scores.static_change_mean_px > 0  # noise moved it
    assert all(f.disparity_range_px == take.source.disparity_range for f in off.frames)  # grid's own plan
    table = format_video_table(result)
    assert table.count("still") == 2 and "flicker" in table
    png = plot_video(result, tmp_path / "video.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(("args", "says"), [(["--frames", "1"], "--frames"), (["--preset", "nope"], "--preset")])
def test_bench_video_refuses_bad_options_in_one_line(args: list[str], says: str) -> None:
    from tests_support import run_rigctl

    res = run_rigctl("bench", "depth", "--video", *args)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and says in res.stderr, res.stderr
