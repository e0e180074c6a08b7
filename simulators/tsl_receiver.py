"""A simulated TSL UMD 3.1 tally receiver on a pseudo-terminal, with a stable device path (a symlink, as
udev gives a USB-serial adapter) and faults on purpose: unplug, replug, garbage on the line."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from rigctl.drivers.protocols import tsl31
from rigctl.simulators.pty_line import PtyDevice


class SimTslReceiver(PtyDevice):
    def __init__(self, link: Path) -> None:
        super().__init__(link, "sim-tsl")
        self.frames: list[tuple[float, tsl31.Tsl31Message]] = []
        self._lock = threading.Lock()
        self._decoder = tsl31.Tsl31Decoder()
        self.plug()

    def plug(self) -> None:
        self._decoder = tsl31.Tsl31Decoder()
        super().plug()

    def on_data(self, fd: int, data: bytes) -> None:
        now = time.monotonic()
        with self._lock:
            self.frames.extend((now, m) for m in self._decoder.feed(data))

    def since(self, t: float) -> list[tsl31.Tsl31Message]:
        with self._lock:
            return [m for ts, m in self.frames if ts >= t]

    def first_after(self, t: float) -> float | None:
        with self._lock:
            return next((ts for ts, _ in self.frames if ts >= t), None)
