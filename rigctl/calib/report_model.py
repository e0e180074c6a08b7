"""The calibration report as types: what ``rigctl calibrate`` measured per camera and overall, the held-out
rectification residuals and the solve's steps. ``as_dict`` gives the JSON of ``rigctl calibrate --json``
(keys a measurement did not produce are left out, as before)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from rigctl.calib.solve import FitStep


@dataclass
class ErrorStats:
    """Residuals in pixels: RMS, 95th percentile and largest magnitude, over ``n`` corners (NaN when n = 0)."""

    rms: float
    p95: float
    max: float
    n: int


@dataclass
class RawNet:
    raw: ErrorStats  # what matching sees
    net: ErrorStats  # less the parallax the cameras' fitted positions off the lattice predict


@dataclass
class PairResidual:
    direction: str  # "horizontal" or "vertical" neighbours
    raw: ErrorStats
    net: ErrorStats


@dataclass
class DisparityRatio:
    median: float  # horizontal over vertical disparity of the same corner
    expected_dx_over_dy: float
    relative: float


@dataclass
class RectificationResiduals:
    """Cross-disparity after common-plane rectification, on frames held out of the fit."""

    frames: int
    vertical_between_horizontal_neighbours: RawNet
    horizontal_between_vertical_neighbours: RawNet
    pairs: dict[str, PairResidual]
    disparity_ratio: DisparityRatio | None
    held_out_frames: list[str] = field(default_factory=list)


@dataclass
class CameraReport:
    rms_px: float
    frames_used: int
    frames_rejected: list[str]
    rotation_vs_common_deg: float
    coverage: float  # share of image cells with corners
    corner_cells: int
    distortion_monotonic: bool
    focal_px: float
    uncertainty: dict[str, float]  # 1-sigma, by parameter
    position_vs_nominal_mm: list[float] | None = None  # when the take's rig gives nominal positions
    position_vs_centroid: list[float] | None = None  # otherwise
    cross_validation_px: float | None = None
    truth: dict[str, float] | None = None  # against a true calibration: centre_mm, rotation_deg, ray_deg
    input_name: str | None = None


@dataclass
class CalibrationReport:
    source: str
    target: str
    cameras: dict[str, CameraReport]
    rms_px: float
    frames: int
    frames_with_rejected_views: list[str]
    rejected_corners: int
    rejected_views: list[tuple[str, str]]  # camera, frame
    rectification_residuals: RectificationResiduals | None
    cross_validation_px: dict[str, float] | None
    truth: bool
    diagnosis: list[str]
    history: list[FitStep]
    timings_s: dict[str, float]

    def as_dict(self) -> dict[str, object]:
        out: dict[str, object] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "cameras":
                out[f.name] = {n: _without_none(dataclasses.asdict(c)) for n, c in value.items()}
            elif f.name == "history":
                out[f.name] = [step.as_dict() for step in value]
            elif f.name == "rejected_views":
                out[f.name] = [list(v) for v in value]
            elif f.name == "rectification_residuals":
                out[f.name] = dataclasses.asdict(value) if value is not None else None
            else:
                out[f.name] = value
        return out


def _without_none(d: dict[str, object]) -> dict[str, object]:
    return {k: v for k, v in d.items() if v is not None}
