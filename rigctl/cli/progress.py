"""A progress bar on stderr for long work (only when stderr is a terminal; silent in CI logs)."""

from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, label: str, enabled: bool | None = None) -> None:
        self.label = label
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self._last = 0.0
        self.started = time.monotonic()

    def __call__(self, fraction: float, detail: str = "") -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.1 and fraction < 1.0:
            return
        self._last = now
        width = 30
        filled = round(width * max(0.0, min(1.0, fraction)))
        bar = "#" * filled + "-" * (width - filled)
        sys.stderr.write(f"\r{self.label} [{bar}] {fraction * 100:5.1f}% {detail}".ljust(78))
        sys.stderr.flush()

    def steps(self, done: int, total: int) -> None:
        self(done / max(total, 1), f"{done}/{total}")

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()
