"""A take's capture times as ``take.proof`` judges them: one late timestamp (a driver starved of CPU stamps a
late frame late and the next on time, as the kernel's vivid devices do under load) is a take to read; three
frames within one period, or times that go backwards, are not."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rigctl.take.index import DTYPE, RECORD_SIZE
from rigctl.take.proof import record_problems

PERIOD = 40_000_000  # 25 fps
SIZE = 100


def _index(times: list[int]) -> np.ndarray:
    idx = np.zeros(len(times), DTYPE)
    idx["size"] = SIZE
    idx["offset"] = np.arange(len(times)) * SIZE
    idx["sequence"] = np.arange(len(times))
    idx["capture_ns"] = times
    return idx


def _problems(times: list[int]) -> list[str]:
    return record_problems(Path("cam.index"), _index(times), SIZE, PERIOD)


def test_steady_times_and_one_late_frame_are_a_take() -> None:
    steady = [10**9 + k * PERIOD for k in range(10)]
    assert _problems(steady) == []
    late = list(steady)
    late[4] += 23_000_000  # 63 ms after the frame before, 17 ms before the next
    assert _problems(late) == []


def test_three_frames_within_one_period_are_refused_at_the_third() -> None:
    times = [10**9 + k * PERIOD for k in range(10)]
    times[5] = times[4] + 15_000_000
    times[6] = times[4] + 30_000_000  # frames 4, 5 and 6 within 30 ms
    (problem,) = _problems(times)
    assert f"byte {6 * RECORD_SIZE}:" in problem and "faster than the rate allows" in problem


def test_a_sustained_fast_rate_and_backward_times_are_refused() -> None:
    assert "faster than the rate allows" in _problems([10**9 + k for k in range(10)])[0]
    assert "goes backwards" in _problems([10**9, 10**9 + PERIOD, 10**9 + PERIOD])[0]
    assert _problems([10**9, 10**9 + 1]) == []  # two frames: a single step says nothing of the rate
