"""What a depth run is asked for: the preset, the plan (a range or near/far distances), keying, cameras,
temporal stabilisation and the chunking of a take into runs of consecutive frame sets."""

from __future__ import annotations

from dataclasses import dataclass

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
