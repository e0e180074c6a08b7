"""A simulated TSL UMD 3.1 tally receiver on a pseudo-terminal, with a stable device path (a symlink, as
udev gives a USB-serial adapter) and faults on purpose: unplug, replug, garbage on the line."""

from __future__ import annotations

import os
import select
import threading
import time
from pathlib import Path

from rigctl.drivers.protocols import tsl31


class SimTslReceiver:
    def __init__(self, link: Path) -> None:
        self.link = Path(link)
        self.frames: list[tuple[float, tsl31.Tsl31Message]] = []
        self._lock = threading.Lock()
        self._master = self._slave = -1
        self._thread: threading.Thread | None = None
        self._plugged = threading.Event()
        self.plug()

    def plug(self) -> None:
        """A new line appears at the same path (like a replugged adapter)."""
        self._master, self._slave = os.openpty()
        tmp = self.link.with_name(self.link.name + ".new")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(os.ttyname(self._slave))
        tmp.replace(self.link)
        self._plugged.set()
        self._thread = threading.Thread(target=self._read, args=(self._master,), daemon=True)
        self._thread.start()

    def unplug(self) -> None:
        """The line goes away: the path disappears and writes on the old line fail."""
        self._plugged.clear()
        self.link.unlink(missing_ok=True)
        master, slave = self._master, self._slave
        self._master = self._slave = -1
        if self._thread:
            self._thread.join(timeout=2)
        os.close(master)
        os.close(slave)

    def _read(self, fd: int) -> None:
        dec = tsl31.Tsl31Decoder()
        while self._plugged.is_set() and fd == self._master:
            r, _, _ = select.select([fd], [], [], 0.05)
            if not r:
                continue
            try:
                data = os.read(fd, 65536)
            except OSError:
                return
            now = time.monotonic()
            with self._lock:
                self.frames.extend((now, m) for m in dec.feed(data))

    def since(self, t: float) -> list[tsl31.Tsl31Message]:
        with self._lock:
            return [m for ts, m in self.frames if ts >= t]

    def first_after(self, t: float) -> float | None:
        with self._lock:
            return next((ts for ts, _ in self.frames if ts >= t), None)

    def close(self) -> None:
        if self._master >= 0:
            self.unplug()
