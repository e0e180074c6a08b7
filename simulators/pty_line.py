"""The line a simulated serial device sits on: a pseudo-terminal pair, so the host side goes through the real
pyserial and termios path, optionally behind a stable symlink (as udev gives a USB-serial adapter), with
unplug and replug on purpose."""

from __future__ import annotations

import os
import select
import threading
from pathlib import Path


class PtyDevice:
    """Serves ``on_data`` with whatever the host writes; ``port`` is what the host opens."""

    def __init__(self, link: Path | None = None, name: str = "sim-serial") -> None:
        self.link = Path(link) if link else None
        self.port = ""
        self._name = name
        self._master = self._slave = -1
        self._plugged = threading.Event()
        self._thread: threading.Thread | None = None

    def on_data(self, fd: int, data: bytes) -> None:
        """Bytes from the host; reply with ``os.write(fd, ...)``."""
        raise NotImplementedError

    def plug(self) -> None:
        """A new line appears (at the same path, like a replugged adapter)."""
        self._master, self._slave = os.openpty()
        self.port = os.ttyname(self._slave)
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".new")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(self.port)
            tmp.replace(self.link)
            self.port = str(self.link)
        self._plugged.set()
        self._thread = threading.Thread(target=self._serve, args=(self._master,), name=self._name, daemon=True)
        self._thread.start()

    def unplug(self) -> None:
        """The line goes away: the path disappears and the host's writes on the old line fail."""
        self._plugged.clear()
        if self.link is not None:
            self.link.unlink(missing_ok=True)
        master, slave = self._master, self._slave
        self._master = self._slave = -1
        if self._thread:
            self._thread.join(timeout=2)
        os.close(master)
        os.close(slave)

    def close(self) -> None:
        if self._master >= 0:
            self.unplug()

    def _serve(self, fd: int) -> None:
        while self._plugged.is_set() and fd == self._master:
            r, _, _ = select.select([fd], [], [], 0.05)
            if not r:
                continue
            try:
                data = os.read(fd, 65536)
            except OSError:
                return
            try:
                self.on_data(fd, data)
            except OSError:
                return
