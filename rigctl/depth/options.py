"""What a depth run is asked for: the preset, the plan (a range or near/far distances), keying, cameras,
temporal stabilisation and the chunking of a take into runs of consecutive frame sets."""

from __future__ import annotations

from dataclasses import dataclass

# Frame sets per chunk: the temporal stabiliser starts afresh at every chunk (and every chunk starts from the
# take's search range), so a farm hands chunks to workers independently and any chunking run in one process
# gives the same bytes. 10 frame sets are 0.4 s at 25 fps: a take of a minute is 150 chunks for a farm.
DEFAULT_CHUNK = 10
# Frame sets before a chunk's first that it processes first (not written): the stabiliser's running mean
# settles on them, so the chunk's first frame does not pop by the single-frame noise. Measured in the README.
DEFAULT_WARMUP = 8


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
