"""``DIR/process.json``: what happened to every frame set, rewritten atomically after each one, so a run that
is stopped at any moment leaves a ledger a re-run can trust."""

from __future__ import annotations

import json
import logging
import math
import os
from pathlib import Path
from typing import Any

from rigctl.errors import TakeError

log = logging.getLogger(__name__)

LEDGER = "process.json"


class Ledger:
    def __init__(self, out: Path) -> None:
        self.path = out / LEDGER
        self.frames: dict[str, dict[str, Any]] = {}
        if self.path.exists():
            try:
                data = json.loads(self.path.read_text())
                frames = data["frames"]
                if not isinstance(frames, dict):
                    raise TypeError
            except (OSError, ValueError, KeyError, TypeError):
                raise TakeError(f'{self.path}: not a process ledger (expected {{"frames": {{...}}}})') from None
            self.frames = frames

    def done(self, name: str) -> bool:
        return self.frames.get(name, {}).get("status") == "done"

    def record(self, name: str, entry: dict[str, Any]) -> None:
        self.frames[name] = entry
        self.save()

    def save(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f".{LEDGER}.{os.getpid()}.tmp")
        data = {"frames": dict(sorted(self.frames.items()))}
        tmp.write_text(json.dumps(data, indent=1, default=_finite, allow_nan=False))
        os.replace(tmp, self.path)


def _finite(value: Any) -> Any:
    """JSON never holds NaN or infinity: numpy scalars become floats, non-finite ones null."""
    v = float(value)
    return v if math.isfinite(v) else None
