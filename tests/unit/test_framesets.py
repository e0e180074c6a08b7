"""Frame-set assembly by capture time (``rigctl.take.framesets.assemble``): every frame in its own set, also
when a host starved of CPU stamps one frame more than half a period late (or early) and its neighbour on time,
as the kernel's vivid devices did beside two CPU-bound processes in CI; real gaps stay gaps."""

from __future__ import annotations

import numpy as np
import pytest

from rigctl.take.framesets import FrameSet, assemble

PERIOD = 40_000_000  # 25 fps
CAMS = ("r0c0", "r0c1", "r1c0")
T0 = 1_000_000_000


def stamps(frames: int = 12, seed: int = 0) -> dict[str, np.ndarray]:
    """Genlocked cameras: frame n of every camera at n periods, with up to 0.3 ms of host jitter."""
    rng = np.random.default_rng(seed)
    return {c: T0 + np.arange(frames, dtype=np.int64) * PERIOD + rng.integers(0, 300_000, frames) for c in CAMS}


def by_frame(sets: list[FrameSet]) -> dict[int, dict[str, int]]:
    return {s.number: dict(s.members) for s in sets}


def test_on_time_frames_make_complete_sets_in_order() -> None:
    sets = assemble(stamps(), PERIOD, T0)
    assert len(sets) == 12
    assert all(s.members == {c: s.number for c in CAMS} for s in sets)


@pytest.mark.parametrize("late_ms", [21, 23, 30, 38])
def test_a_frame_stamped_late_stays_in_its_set_and_its_neighbour_in_the_next(late_ms: int) -> None:
    ts = stamps()
    ts["r0c1"][4] += late_ms * 1_000_000  # more than half a period late; frame 5 on time
    sets = by_frame(assemble(ts, PERIOD, T0))
    assert sets[4] == {c: 4 for c in CAMS}  # before: r0c1 missing here ...
    assert sets[5] == {c: 5 for c in CAMS}  # ... and its frame 4 here in place of frame 5
    assert all(sets[n] == {c: n for c in CAMS} for n in range(12))


def test_the_late_stamp_shows_in_its_sets_spread_not_in_its_time() -> None:
    ts = stamps()
    ts["r1c0"][6] += 25_000_000
    sets = assemble(ts, PERIOD, T0)
    assert sets[6].spread_ns >= 24_700_000
    assert abs(sets[6].time_ns - (T0 + 6 * PERIOD)) < 300_000  # the others' time: the rig's phase
    assert all(s.spread_ns < 300_000 for s in sets if s.number != 6)


@pytest.mark.parametrize("frame", [3, 11])  # the last frame too: carried into a set of its own
def test_a_frame_stamped_early_goes_on_to_its_own_set(frame: int) -> None:
    ts = stamps()
    ts["r0c0"][frame] -= 23_000_000  # more than half a period early; the frame before on time
    sets = by_frame(assemble(ts, PERIOD, T0))
    assert len(sets) == 12
    assert all(sets[n] == {c: n for c in CAMS} for n in range(12))


def test_a_dropped_frame_is_a_gap_and_later_sets_are_not_shifted() -> None:
    ts = stamps()
    ts["r0c1"] = np.delete(ts["r0c1"], 4)  # frame 4 never arrived: index 4 is frame 5 now
    sets = by_frame(assemble(ts, PERIOD, T0))
    assert sets[4] == {"r0c0": 4, "r1c0": 4}
    assert sets[5] == {"r0c0": 5, "r0c1": 4, "r1c0": 5}
    assert all(sets[n]["r0c1"] == n - 1 for n in range(5, 12))


def test_a_dropped_frame_then_a_late_one_is_not_pulled_back_past_a_period() -> None:
    """Frame 4 lost and frame 5 stamped late by 30 ms: set 4 stays a gap (frame 5 is more than a period
    after it) and set 5 takes frame 5, not a neighbour's."""
    ts = stamps()
    ts["r0c1"][5] += 30_000_000
    ts["r0c1"] = np.delete(ts["r0c1"], 4)
    sets = by_frame(assemble(ts, PERIOD, T0))
    assert "r0c1" not in sets[4]
    assert sets[6]["r0c1"] == 5  # index 5 is frame 6, on time
    assert sets[5]["r0c1"] == 4  # frame 5, less than a period late for its set


def test_two_frames_at_one_instant_keep_the_first() -> None:
    ts = stamps()
    ts["r1c0"] = np.insert(ts["r1c0"], 3, ts["r1c0"][2] + 1_000)  # a duplicate 1 us after frame 2
    sets = by_frame(assemble(ts, PERIOD, T0))
    assert sets[2]["r1c0"] == 2
    assert all(sets[n]["r1c0"] == n + 1 for n in range(3, 12))  # later indices shifted by the duplicate
    assert len(sets) == 12
