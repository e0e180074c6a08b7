"""The take-level pipeline (rigctl.depth.pipeline) over takes of the simulator held in memory (every frame,
the same bytes: no capture clock involved): the range is decided once per take and only ever widened, the
state starts afresh at every chunk, and nothing under the CLI, the shoot UI, the demo or the farm runs the
depth stages itself."""

from __future__ import annotations

import ast
import gc
import itertools
import json
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import rigctl.depth.take_range as take_range
from rigctl.depth import measured_range as measured_module
from rigctl.depth.grid import Grid
from rigctl.depth.options import DepthOptions
from rigctl.depth.packed import PackedField
from rigctl.depth.pipeline import FrameDone, TakeProcessor, chunks
from rigctl.depth.scenes import surfaces
from rigctl.depth.take_range import RangeDecision
from rigctl.simulated_presenter import presenter_video
from rigctl.timecode import Timecode

REPO = Path(__file__).resolve().parents[2]
FRAMES = 6


@pytest.fixture(scope="module")
def moving_ideal(module_tmp: Callable[[str], Path]) -> Any:
    """An ideal presenter take at 480x270 whose presenter moves every frame set (seed 3, as in issue 23)."""
    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", "width_px: 480").replace("height_px: 540", "height_px: 270")
    path = module_tmp("rig") / "small.yaml"
    path.write_text(rig)
    return presenter_video(True, FRAMES, ideal=True, seed=3, rig_name=str(path))


def test_a_moving_take_without_a_plan_is_matched_once_and_never_searches_a_narrower_range(
    moving_ideal: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    passes: list[int] = []
    votes: list[int] = []
    real_measured, real_votes = take_range.measured_range, measured_module.disparity_votes

    def counting_measured(grids: Any, *a: Any) -> Any:
        passes.append(len(grids))
        return real_measured(grids, *a)

    def counting_votes(grid: Grid, *a: Any) -> Any:
        votes.append(int(grid.meta["frame"]))
        return real_votes(grid, *a)

    monkeypatch.setattr(take_range, "measured_range", counting_measured)
    monkeypatch.setattr(measured_module, "disparity_votes", counting_votes)
    opt = DepthOptions(cameras=("r1c1",), chunk=FRAMES)
    processor = TakeProcessor(moving_ideal, opt)
    done = [d for d in processor.run_chunk(moving_ideal.frame_numbers()) if isinstance(d, FrameDone)]
    assert len(done) == FRAMES
    # one feature-matching pass for the whole take, on frame sets spread across it, none per frame set
    assert passes == [3] and votes == [0, 2, 5]
    assert not processor.decision.planned and processor.decision.sampled_frames == [0, 2, 5]
    ranges = [d.report.disparity_range_px for d in done]
    for (lo0, hi0), (lo1, hi1) in itertools.pairwise(ranges):
        assert lo1 <= lo0 and hi1 >= hi0  # never narrower than an earlier frame set's
    lo, hi = processor.decision.disparity_range_px
    truths = [d.grid.truth["r1c1"] for d in done if d.grid.truth]
    finite = np.concatenate([t[np.isfinite(t)] for t in truths])
    assert lo < finite.min() and finite.max() < hi  # the measured range covers the scene ...
    assert sum(d.report.bound_hit_pixels for d in done) == 0  # ... so nothing is clipped at its bounds
    assert not processor.widenings
    with np.errstate(invalid="ignore"):
        moved = [np.abs(a - b)[np.isfinite(a) & np.isfinite(b)].max() for a, b in itertools.pairwise(truths)]
    assert min(moved) > 0.1  # the presenter did move in every frame set


class StillScene:
    """A stratified scene as a take of ``frames`` identical frame sets (its truth spans about -4..6 px)."""

    flat = False
    doffs = 0.0
    disparity_range = None

    def __init__(self, frames: int) -> None:
        self.base = surfaces((64, 64), 0)
        self.names = list(self.base.names)
        self.focal_px, self.spacing = self.base.focal_px, self.base.spacing
        self.frames = frames

    @property
    def name(self) -> str:
        return "still scene"

    def frame_numbers(self) -> list[int]:
        return list(range(self.frames))

    def timing(self, number: int) -> tuple[float | None, Timecode | None]:
        return None, None

    def grid(self, number: int) -> Grid:
        b = self.base
        return Grid(
            list(b.names), b.images, dict(b.offsets), b.focal_px, b.spacing, truth=b.truth, meta={"frame": number}
        )


def test_a_measured_range_that_clips_the_scene_is_widened_the_frame_set_run_again_and_kept() -> None:
    source = StillScene(3)
    assert source.base.truth is not None
    t = source.base.truth["r1c1"]
    top = float(t[np.isfinite(t)].max())
    narrow = RangeDecision(disparity_range_px=(-6.0, top - 3.0), source="measured (test)", planned=False)
    processor = TakeProcessor(source, DepthOptions(preset="balanced", cameras=("r1c1",), key=False), narrow)
    done = [d for d in processor.run_chunk([0, 1, 2]) if isinstance(d, FrameDone)]
    first = done[0].report
    assert first.widenings and first.widenings[0].high_hits > 0 and first.widenings[0].low_hits == 0
    lo, hi = first.disparity_range_px
    assert lo == -6.0 and hi > top  # widened on the side that was hit until the scene fits
    assert "(widened)" in first.range_source
    assert [d.report.disparity_range_px for d in done[1:]] == [(lo, hi)] * 2  # kept, never narrowed again
    assert not done[1].report.widenings
    # the clipped first estimate was not kept: the frame set's result is the one over the widened range
    r1c1 = done[0].results["r1c1"].disparity
    assert float(np.nanmax(np.where(np.isfinite(r1c1), r1c1, np.nan))) > top - 3.0 + 0.5
    processor.start_chunk()  # a new chunk starts from the take's range, as a farm worker would
    assert processor.d_range == narrow.disparity_range_px


def test_a_planned_range_is_never_widened() -> None:
    source = StillScene(1)
    plan = RangeDecision(disparity_range_px=(-6.0, 2.0), source="given disparity range", planned=True)
    processor = TakeProcessor(source, DepthOptions(preset="balanced", cameras=("r1c1",), key=False), plan)
    done = processor.process(0)
    assert done.report.disparity_range_px == (-6.0, 2.0) and not done.report.widenings
    assert done.report.bound_hit_pixels > 0  # reported, as the plan's word stands


def test_chunks_are_runs_of_consecutive_frame_sets() -> None:
    assert chunks([3, 4, 5, 7, 8], 2) == [[3, 4], [5, 7], [8]]
    assert chunks([1], 10) == [[1]]
    with pytest.raises(Exception, match="--chunk must be at least 1"):
        chunks([1], 0)


# the stages themselves; a caller may hand work to the pipeline (TakeProcessor, run_depth) or ask it for the
# take's range (decide_range: the farm does before handing out chunks)
DEPTH_STAGES = {"estimate", "cross_check", "depth_grid", "measured_range", "write_outputs", "Temporal", "Keyer"}


def test_no_module_under_cli_tui_demo_or_farm_runs_the_depth_stages_itself() -> None:
    """They hand a source and options to the pipeline; keying, estimating, cross-checking, deciding the range
    and exporting happen in rigctl.depth alone."""
    roots = [*(REPO / "rigctl" / "cli").glob("*.py"), *(REPO / "rigctl" / "tui").glob("*.py"),
             *(REPO / "rigctl" / "farm").glob("*.py"), REPO / "rigctl" / "demo.py"]  # fmt: skip
    offenders = []
    for path in roots:
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("rigctl.depth"):
                used = {a.name for a in node.names} & DEPTH_STAGES
                if used:
                    offenders.append(f"{path.relative_to(REPO)} imports {sorted(used)} from {node.module}")
                if node.module in ("rigctl.depth.estimate", "rigctl.keying", "rigctl.depth.measured_range"):
                    offenders.append(f"{path.relative_to(REPO)} imports {node.module}")
    assert offenders == []


def test_rigctl_depth_reports_the_take_range_bound_hits_and_flicker_of_a_recorded_take(tmp_path: Path) -> None:
    from tests_support import run_rigctl

    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", "width_px: 480").replace("height_px: 540", "height_px: 270")
    (tmp_path / "small.yaml").write_text(rig)
    res = run_rigctl(
        "record", str(tmp_path / "small.yaml"), "--take", "t", "--frames", "3", "--out", str(tmp_path),
        "--sim", "ideal=true", "--sim", "deterministic=true", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    out = tmp_path / "d"
    res = run_rigctl("depth", str(tmp_path / "t"), "--out", str(out), "--preset", "fast", "--cameras", "r1c1",
                     "--chunk", "2", "--json")  # fmt: skip
    assert res.returncode == 0, res.stderr
    report = json.loads((out / "report.json").read_text())
    assert report == json.loads(res.stdout)
    assert report["range"]["sampled_frames"] == [0, 1, 2] and report["range"]["planned"] is False
    assert report["chunk"] == 2 and report["temporal"] is True
    frames = report["frames"]
    assert sorted(frames) == ["0", "1", "2"]
    assert report["bound_hit_pixels"] == sum(f["bound_hit_pixels"] for f in frames.values())
    assert report["widenings"] == [w for n in ("0", "1", "2") for w in frames[n]["widenings"]]
    lo, hi = report["range"]["disparity_range_px"]
    for n in ("0", "1", "2"):  # each frame set searched at least the take's range, widened where it was hit
        f_lo, f_hi = frames[n]["disparity_range_px"]
        assert f_lo <= lo and f_hi >= hi
        for w in frames[n]["widenings"]:
            assert w["after"][0] <= w["before"][0] and w["after"][1] >= w["before"][1]
    assert frames["1"]["disparity_range_px"][0] <= frames["0"]["disparity_range_px"][0]  # same chunk: never
    assert frames["1"]["disparity_range_px"][1] >= frames["0"]["disparity_range_px"][1]  # narrower
    video = report["video"]["r1c1"]  # the take has a truth: flicker per camera
    assert video["frames"] == 3 and video["pairs"] == 2 and video["changing_pixels"] > 0
    assert video["change_error_mean_px"] is not None and video["change_error_mean_px"] >= 0
    bad = run_rigctl("depth", str(tmp_path / "t"), "--out", str(out), "--chunk", "0")
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "--chunk" in bad.stderr, bad.stderr


def test_a_frame_set_is_let_go_of_once_the_next_one_is_done_but_for_what_the_next_reads(moving_ideal: Any) -> None:
    """Issue 24, a chunk's memory: the temporal state keeps of a frame set only its half-size pictures, the
    final disparities and the frames in each pixel's mean; not its pictures (and their grey), nor the rest
    of its results. Once a consumer has let go of a frame set (the farm's and ``rigctl depth``'s loops do),
    nothing holds it through the next frame set's depth, and the stabiliser still stabilises."""
    processor = TakeProcessor(moving_ideal, DepthOptions(cameras=("r1c1", "r1c2"), chunk=3))
    grids, results, blended = [], [], []
    for done in processor.run_chunk([0, 1, 2]):
        assert isinstance(done, FrameDone)
        gc.collect()
        assert all(ref() is None for ref in grids + results)  # every frame set before this one is gone
        grids.append(weakref.ref(done.grid))
        results += [weakref.ref(r) for r in done.results.values()]
        blended.append(done.results["r1c1"].stats.get("temporal_blended_share", 0.0))
        kept = processor.temporal.previous
        assert kept is not None and set(kept.disparity) == {"r1c1", "r1c2"}
        # the results' packed planes themselves (``packed.py``), not a copy of each
        assert all(kept.disparity[c] is PackedField.held(done.results[c], "disparity") for c in kept.disparity)
        assert kept.pictures.grid is None and set(kept.pictures.pictures) == set(done.grid.names)
        h, w = done.grid.shape
        assert all(p.shape == ((h + 1) // 2, (w + 1) // 2, 3) for p in kept.pictures.pictures.values())
        del done, kept
    assert blended[0] == 0.0 and max(blended[1:]) > 0  # the later frame sets were stabilised against the earlier


def test_a_frame_sets_greys_and_8_bit_copies_are_let_go_of_before_its_write(moving_ideal: Any) -> None:
    """Issue 24, the write's peak: the estimates keep every camera's grey (and a take's 8-bit copies) for the
    frame set; once its depth is done nothing made from the pictures is held through the write."""
    processor = TakeProcessor(moving_ideal, DepthOptions(cameras=("r1c1", "r1c2")))
    grid = moving_ideal.grid(0)
    made: list[int] = []
    processor.depth(grid, 0, progress=lambda cam: made.append(grid.frames.made_bytes()))
    h, w = grid.shape
    assert made[1] >= 9 * h * w * 4  # the first camera's estimate made the nine greys the second one read
    assert grid.frames.made_bytes() == 0
