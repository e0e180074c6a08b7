"""What a depth run reports, typed: per frame set (:class:`FrameReport`: what ``report.json`` holds per frame
and the farm's ledger per done frame) and per take (:class:`TakeReport`: ``report.json``). Dicts only where
the JSON is read or written."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from rigctl.depth.search import EstimateStats
from rigctl.depth.take_range import RangeDecision, SearchRounds, Widening
from rigctl.depth.video_metrics import VideoScores
from rigctl.publish import publish_json
from rigctl.take.manifest import DamagedFrame


class TruthScores(BaseModel):
    """One camera's estimate against the truth (:func:`rigctl.depth.metrics.score`)."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    bad_0_1: float = Field(alias="bad_0.1")
    bad_0_2: float = Field(alias="bad_0.2")
    bad_0_5: float = Field(alias="bad_0.5")
    bad_1_0: float = Field(alias="bad_1.0")
    bad_2_0: float = Field(alias="bad_2.0")
    mae_px: float | None
    rms_px: float | None
    mse_x100: float | None
    locking_pct: float | None
    no_estimate_pct: float
    false_fg_pct: float = 0.0  # depth where the truth has none, % of the truth's pixels (0 in older reports)
    missed_fg_pct: float = 0.0  # the truth's pixels with no depth, %
    false_fg_pixels: int = 0
    pixels: int


class CameraDepth(EstimateStats, total=False):
    """One camera of a frame set: its estimator statistics and, when the take has a truth, its scores."""

    against_truth: TruthScores


class Timings(BaseModel):
    model_config = ConfigDict(extra="forbid")

    load: float = 0.0
    depth: float = 0.0
    write: float = 0.0
    write_cpu: float = 0.0  # CPU seconds of the process while it wrote


class FrameReport(BaseModel):
    """One frame set: the range searched and why, what was left out, each camera's estimator statistics
    (``against_truth`` when the take has a truth), bound hits, the range's widenings, the stages' times."""

    model_config = ConfigDict(extra="forbid")

    disparity_range_px: tuple[float, float]
    range_source: str
    levels_skipped_by_plan: float
    keyed_background_share: float
    bound_hit_pixels: int
    widenings: list[Widening] = []
    cameras: dict[str, CameraDepth]
    timings_s: Timings

    def truth(self, camera: str) -> TruthScores | None:
        cam = self.cameras.get(camera)
        return cam.get("against_truth") if cam is not None else None

    def to_json(self) -> dict[str, Any]:
        return self.model_dump(mode="json", by_alias=True)


class TakeReport(BaseModel):
    """What ``rigctl depth`` did (``report.json``)."""

    model_config = ConfigDict(extra="forbid")

    source: str
    preset: str
    range: RangeDecision
    search: SearchRounds | None = None  # how the take's range settled: what every frame set searched
    chunk: int
    warmup: int = 0
    temporal: bool
    frames: dict[str, FrameReport] = {}
    bound_hit_pixels: int = 0  # summed over the frame sets
    widenings: list[Widening] = []  # widenings within the published frame sets, in order (none once settled)
    video: dict[str, VideoScores] = {}  # per camera, when the take has a truth
    damaged_skipped: list[DamagedFrame] = []
    seconds: float = 0.0

    def to_json(self) -> dict[str, Any]:
        data = self.model_dump(mode="json", by_alias=True, exclude={"damaged_skipped"})
        if self.damaged_skipped:
            data["damaged_skipped"] = [d.model_dump(mode="json", exclude_none=True) for d in self.damaged_skipped]
        return data

    def write(self, path: Path) -> None:
        publish_json(path, self.to_json())
