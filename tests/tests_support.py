"""Helpers for tests (never imported by runtime code)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def rigctl_exe() -> list[str]:
    exe = Path(sys.executable).with_name("rigctl")
    return [str(exe)]


def run_rigctl(*argv: str, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*rigctl_exe(), *argv], cwd=cwd, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL
    )
