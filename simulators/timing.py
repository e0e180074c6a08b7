"""When each simulated camera's frames are captured: the genlocked grid, the start-up stagger, skew, jitter,
signal loss and the sequence numbers a camera drops at the source. Pure functions of the settings and the
seed, so a take's timing is the same on any machine."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from rigctl.simulators.settings import SimSettings

# deterministic capture: the simulated clock's origin (the genlocked grid's frame 0), the same on every machine
SIMULATED_ORIGIN_NS = 1_000_000_000_000


@dataclass(frozen=True)
class FrameTiming:
    """When a camera's frame was captured, which sequence number it carries and what it shows."""

    sequence: int
    capture_ns: int  # relative to the array's stream start
    scene_frame: int  # index on the common (genlocked) frame grid
    delivered: bool  # False: dropped at the source


def start_offset(settings: SimSettings, names: list[str], name: str, period_ns: int) -> int:
    """Start-up stagger: camera ``name``'s first frame is a whole number of periods after stream start."""
    rng = np.random.default_rng(np.random.SeedSequence([settings.seed, 4]))
    most = int(settings.stagger_ms * 1e6 // period_ns)
    offsets = {n: int(rng.integers(0, most + 1)) if most else 0 for n in names}
    return offsets[name]


def frame_timings(
    settings: SimSettings, name: str, index: int, period_ns: int, first_grid: int, offset: int = 0
) -> Iterator[FrameTiming]:
    """Frame timings of camera ``name`` (``index`` in the array) after it starts streaming at grid slot
    ``first_grid`` plus its start-up ``offset`` (an endless generator). Sequence numbers start at 0, as after
    a V4L2 STREAMON."""
    s = settings
    skew_ns = int(s.skew_us.get(name, 0.0) * 1e3)
    drops = set(s.drops.get(name, []))
    loss = s.signal_loss.get(name)
    rng = np.random.default_rng(np.random.SeedSequence([s.seed, 5, index]))
    grid = first_grid + offset
    seq = 0
    while True:
        t_grid = grid * period_ns
        jitter = int(rng.normal(0, s.jitter_us * 1e3)) if s.jitter_us else 0
        if loss is not None and loss[0] * 1e9 <= t_grid < loss[1] * 1e9:
            grid += 1
            continue
        yield FrameTiming(seq, t_grid + skew_ns + jitter, grid, seq not in drops)
        seq += 1
        grid += 1
