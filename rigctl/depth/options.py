"""What a depth run is asked for: the preset, the plan (a range or near/far distances), keying, cameras,
temporal stabilisation and the chunking of a take into runs of consecutive frame sets."""

from __future__ import annotations

from dataclasses import dataclass

# Frame sets per chunk: the state carried from frame set to frame set (the range, the temporal stabiliser)
# starts afresh at every chunk, so a farm hands chunks to workers independently and any chunking run in one
# process gives the same bytes. 10 frame sets are 0.4 s at 25 fps: long enough for the stabiliser to settle,
# short enough to spread a take of a minute (150 chunks) over a farm.
DEFAULT_CHUNK = 10


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
