"""Temporal stability of depth over a take (the seam between the take-level pipeline and the stabiliser).

The pipeline (one ``Temporal`` per run of consecutive frame sets, reset at the start of every chunk the farm
hands out) calls, per frame set:

    for cam in cameras:
        result = estimate(...)                              # this frame set's estimate, as today
        result = temporal.stabilise(grid, cam, result, d_range)
    ... cross-check, write ...
    temporal.advance(grid, results)                         # the frame set's final results become "previous"

``stabilise`` may use the previous frame set's grid (every view's picture) and final results, and must not
touch anything else; with no previous frame set it returns ``result`` unchanged. It records what it did in
``result.stats`` (e.g. the share of pixels whose previous depth was kept). Deterministic: the same frames in
the same order give the same bytes.

This first version is the pass-through that fixes the interface; the stabiliser replaces its body.
"""

from __future__ import annotations

from dataclasses import dataclass

from rigctl.depth.estimate import DepthResult
from rigctl.depth.grid import Grid


@dataclass(frozen=True)
class TemporalParams:
    enabled: bool = True


@dataclass
class Previous:
    grid: Grid
    results: dict[str, DepthResult]


class Temporal:
    """The state carried from one frame set to the next within a run of consecutive frame sets."""

    def __init__(self, params: TemporalParams | None = None) -> None:
        self.params = params or TemporalParams()
        self.previous: Previous | None = None

    def reset(self) -> None:
        self.previous = None

    def stabilise(self, grid: Grid, ref: str, result: DepthResult, d_range: tuple[float, float]) -> DepthResult:
        return result

    def advance(self, grid: Grid, results: dict[str, DepthResult]) -> None:
        self.previous = Previous(grid, dict(results)) if self.params.enabled else None
