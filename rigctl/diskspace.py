"""Free space on a destination, checked before a run writes anything: one way to read it for every verb
(``record``'s preflight, the shoot UI's gauge, ``render``'s refusal up front), and injectable by tests, which
must never depend on this machine's disk."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

from rigctl.errors import DiskFullError, short_path

FreeSpace = Callable[[Path], int]


def free_bytes(folder: Path) -> int:
    """Bytes free to this user on the file system ``folder`` is (or will be) on: its nearest existing ancestor's,
    for an output folder not made yet."""
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return shutil.disk_usage(folder).free


def gb(n: float) -> str:
    """``n`` bytes for a message: in MB below 10 MB (a small take's outputs, a nearly full disk), else in GB."""
    if n < 1e7:
        return f"{n / 1e6:.2f} MB"
    return f"{n / 1e9:.2f} GB" if n < 1e11 else f"{n / 1e9:,.0f} GB"


def check_free_space(folder: Path, need: int, what: str, free_space: FreeSpace | None = None) -> None:
    """Refuse, before any work, a destination whose file system has less than ``need`` bytes free: one line
    naming the option and folder, what is needed (``what``: for what) and what is free (exit 4: the
    destination cannot take it). ``free_space``: the figure, injected by tests; else :func:`free_bytes`."""
    free = (free_space or free_bytes)(folder)
    if need > free:
        raise DiskFullError(
            f"--out {short_path(folder)}: about {gb(need)} needed for {what}, {gb(free)} free on its file system; "
            "free some space or choose another --out"
        )
