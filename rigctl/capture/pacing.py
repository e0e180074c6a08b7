"""How the recorder keeps time with its cameras: live, or paced by a simulated clock.

Live (a real rig, and the simulator by default): now is CLOCK_MONOTONIC, frames are taken as the cameras
deliver them, and a frame that finds no free buffer is lost as a writer drop (capture never waits).

Paced (``--sim deterministic=true``: the cameras deliver each frame when read, on a simulated clock): now is
the latest capture time the recorder has taken, each capture thread holds its first frame until T0 is
decided and waits for a free buffer rather than lose a frame. Which frames make the take, and what they
hold, then does not depend on how fast the machine is.
"""

from __future__ import annotations

import contextlib
import queue
import threading
import time
from collections.abc import Callable, Iterable

import numpy as np

from rigctl.errors import DeviceError
from rigctl.take.accounting import CameraStats
from rigctl.take.plan import FramePool


def grid_phase(captures: list[int], period_ns: int) -> int:
    """The rig's frame phase (capture time modulo the period) from cameras' capture times: their circular
    median, rotated so that phases either side of the wrap-around do not split."""
    ref = captures[0] % period_ns
    offsets = [((c % period_ns - ref + period_ns // 2) % period_ns) - period_ns // 2 for c in captures]
    return int(ref + np.median(offsets)) % period_ns


class Pacing:
    """The recorder's clock and waits. ``wall`` (seconds) bounds the waits for first frames and how long a
    paced camera may stay silent (``stale_s``) before the take stops waiting for it. A paced camera is silent
    only while its frame's scene state renders, which on a machine kept busy by others can take a minute, so
    the bound is generous: it is there for a render that never comes, not for a slow one."""

    def __init__(self, paced: bool, stale_s: float = 300.0, wall: Callable[[], float] = time.monotonic) -> None:
        self.paced = paced
        self.placed = threading.Event()  # T0 is decided
        self.stale_s = stale_s
        self._wall = wall
        self._seen: dict[str, float] = {}
        self._placed_at = 0.0

    @property
    def clock(self) -> str:
        """The clock capture times are on, as the manifest names it."""
        return "simulated" if self.paced else "CLOCK_MONOTONIC"

    def grid_phase(self, stats: list[CameraStats], period_ns: int, first_frame_s: float = 15.0) -> int:
        """The rig's frame phase from the latest frames seen, once every camera delivers. A rig still starting
        up gets ``first_frame_s`` for its first frame, the other cameras a second after it (paced cameras,
        which hold their first frames and are waited for however slow their renders, all get ``stale_s``)."""
        deadline = self._wall() + (self.stale_s if self.paced else first_frame_s)
        while self._wall() < deadline:
            seen = [s.last_capture_ns for s in stats if s.last_capture_ns]
            if len(seen) == len(stats):
                break
            if seen and not self.paced:
                deadline = min(deadline, self._wall() + 1.0)
            time.sleep(0.01)
        seen = [s.last_capture_ns for s in stats if s.last_capture_ns]
        if not seen:
            raise DeviceError("no camera delivers frames: check signal and cabling before recording")
        return grid_phase(seen, period_ns)

    def now(self, stats: Iterable[CameraStats]) -> int:
        if not self.paced:
            return time.monotonic_ns()
        return max((s.last_capture_ns for s in stats), default=0)

    def place(self) -> None:
        """T0 is decided: held frames go on."""
        self._placed_at = self._wall()
        self.placed.set()

    def hold(self, running: threading.Event) -> None:
        """Paced: wait until T0 is decided (or capture ends), so the frame in hand is placed against it."""
        while self.paced and running.is_set() and not self.placed.wait(0.05):
            pass

    def slot(self, pool: FramePool, running: threading.Event) -> int | None:
        """A free buffer; paced, wait for one while capture runs (live: None at once when there is none)."""
        slot = pool.take()
        while slot is None and self.paced and running.is_set():
            with contextlib.suppress(queue.Empty):
                slot = pool.free.get(timeout=0.05)
        return slot

    def seen(self, name: str) -> None:
        if self.paced:
            self._seen[name] = self._wall()

    def stale(self, name: str) -> bool:
        """Paced: the camera has delivered nothing for ``stale_s`` of wall time since T0 or its last frame."""
        return self._wall() - max(self._seen.get(name, 0.0), self._placed_at) > self.stale_s
