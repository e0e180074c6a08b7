"""What a depth run is asked for: the preset, the plan (a range or near/far distances), keying, cameras,
temporal stabilisation and the chunking of a take into runs of consecutive frame sets."""

from __future__ import annotations

import math
from dataclasses import dataclass

from rigctl.errors import ParameterError

# Frame sets per chunk: the temporal stabiliser starts afresh at every chunk (and every chunk starts from the
# take's search state), so a farm hands chunks to workers independently and any chunking run in one process
# gives the same bytes. 50 frame sets are 2 s at 25 fps (a take of a minute is 30 chunks for a farm): a chunk's
# first frame set, where what is left of the pop shows, comes every 2 s.
DEFAULT_CHUNK = 50
# Frame sets before a chunk's first that it processes first, neither written nor reported: the stabiliser's
# running mean (16 frames at most) fills on them, so the chunk's first frame set is not a single-frame estimate
# next to the previous chunk's settled depth. 16 of 50 is a third more compute. Measured in the README.
DEFAULT_WARMUP = 16


@dataclass(frozen=True)
class DepthOptions:
    preset: str = "best"
    near_m: float | None = None
    far_m: float | None = None
    disparity_range: tuple[float, float] | None = None
    key: bool = True
    cameras: tuple[str, ...] | None = None
    margin_px: float = 2.0
    temporal: bool = True
    chunk: int = DEFAULT_CHUNK
    warmup: int = DEFAULT_WARMUP

    def check(self) -> None:
        """Refuse, in one line, options no take could be run with: an unknown preset, a plan whose near
        distance is not below its far one, an empty or non-finite disparity range, a chunk of no frame set, a
        negative warm-up or margin. Needs no take, so a verb checks before it makes a folder or starts a
        cluster (:func:`rigctl.cli.args.depth_options`); the pipeline checks again for its other callers."""
        from rigctl.depth.presets import PRESETS
        from rigctl.planning.planner import check_plan_distances

        if self.preset not in PRESETS:
            raise ParameterError(f"unknown preset {self.preset!r} (presets: {', '.join(PRESETS)})")
        if self.near_m is not None:
            check_plan_distances(self.near_m, self.far_m if self.far_m is not None else math.inf)
        if self.disparity_range is not None:
            lo, hi = (float(v) for v in self.disparity_range)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ParameterError(f"the disparity range must be finite and low below high, got {lo}..{hi} px")
        if not (math.isfinite(self.margin_px) and self.margin_px >= 0):
            raise ParameterError(f"the range margin must be a finite number of pixels >= 0, got {self.margin_px}")
        if self.chunk < 1:
            raise ParameterError(f"--chunk must be at least 1 frame set, got {self.chunk}")
        if self.warmup < 0:
            raise ParameterError(f"--warmup must be at least 0 frame sets, got {self.warmup}")
