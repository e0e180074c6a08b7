"""The recorder's pacing: the grid phase across the wrap-around, the simulated now, and when a paced camera
counts as silent (on an injected wall clock)."""

from __future__ import annotations

import threading

from rigctl.capture.pacing import Pacing, grid_phase
from rigctl.take.accounting import CameraStats
from rigctl.take.plan import FramePool


def test_grid_phase_is_the_circular_median() -> None:
    assert grid_phase([1_000_010, 2_000_020, 3_000_000], 1_000_000) == 10
    # phases either side of the wrap-around: 999_990 and 10 are 20 ns apart, not a period
    assert grid_phase([999_990, 1_000_010, 2_000_005], 1_000_000) == 5


def test_paced_now_is_the_latest_capture_taken_and_the_clock_is_named() -> None:
    stats = [CameraStats("r0c0", last_capture_ns=5), CameraStats("r0c1", last_capture_ns=9)]
    assert Pacing(True).now(stats) == 9
    assert Pacing(True).clock == "simulated" and Pacing(False).clock == "CLOCK_MONOTONIC"


def test_a_paced_camera_is_silent_after_stale_s_of_wall_time_since_t0_or_its_last_frame() -> None:
    wall = [100.0]
    pace = Pacing(True, stale_s=10.0, wall=lambda: wall[0])
    pace.place()
    wall[0] = 109.0
    assert not pace.stale("r0c0")
    pace.seen("r0c0")
    wall[0] = 115.0
    assert not pace.stale("r0c0") and pace.stale("r0c1")
    wall[0] = 119.5
    assert pace.stale("r0c0")


def test_live_never_holds_or_waits_for_a_buffer() -> None:
    running = threading.Event()
    running.set()
    pool = FramePool(1, 16)
    live = Pacing(False)
    live.hold(running)  # returns at once: T0 is never waited for
    assert live.slot(pool, running) == 0 and live.slot(pool, running) is None
    paced = Pacing(True)
    paced.place()
    paced.hold(running)  # T0 decided: goes on at once
    running.clear()
    assert paced.slot(pool, running) is None  # capture ended: stops waiting


def test_paced_cameras_are_waited_for_past_the_live_first_frame_bound() -> None:
    """A paced camera's first frame may wait for a render a busy machine makes slow: its phase still counts,
    where a live rig stops waiting a second after its first camera (wall seconds on an injected clock)."""
    period = 1_000_000

    def run(paced: bool) -> int:
        stats = [CameraStats("r0c0", last_capture_ns=10), CameraStats("r0c1", last_capture_ns=12)]
        late = CameraStats("r0c2")
        calls = [0]

        def wall() -> float:
            calls[0] += 1
            if calls[0] == 40:  # 40 s in: the slow render is done, the third camera delivers
                late.last_capture_ns = 1_000 * period + 500
            return float(calls[0])

        return Pacing(paced, wall=wall).grid_phase([*stats, late], period)

    assert run(paced=False) == 11  # the median of the two that came within the bound
    assert run(paced=True) == 12  # all three: 10, 12 and 500
