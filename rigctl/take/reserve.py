"""The ``.reserve`` file: space kept free on every destination of a recording take, so the final manifest
can still be written when the disk fills.

The recorder holds an exclusive ``flock`` on it for the whole take. The kernel drops the lock when the
process ends, however it ends, so a reserve whose lock can be taken belongs to a take nobody records any
more (the recorder was killed): :func:`remove_stale_reserves` deletes it. A live take's reserve is never
touched.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
from collections.abc import Iterable
from pathlib import Path

log = logging.getLogger(__name__)

RESERVE = ".reserve"


def create_reserve(folder: Path, size: int) -> int:
    """Write ``folder/.reserve`` (``size`` zero bytes) and return its descriptor, locked until closed."""
    fd = os.open(folder / RESERVE, os.O_CREAT | os.O_WRONLY | os.O_TRUNC, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.write(fd, b"\0" * size)
    except OSError:
        os.close(fd)
        raise
    return fd


def release_reserve(folder: Path, fd: int) -> None:
    """Delete the reserve (its space is wanted now) and drop its lock."""
    with contextlib.suppress(OSError):
        (folder / RESERVE).unlink()
    with contextlib.suppress(OSError):
        os.close(fd)


def remove_stale_reserves(folders: Iterable[Path]) -> list[Path]:
    """Delete the reserves in ``folders`` that no running recorder holds; returns those deleted."""
    removed = []
    for folder in folders:
        path = folder / RESERVE
        try:
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            continue  # none, or not ours to open
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue  # a recorder holds it: the take is being recorded
        try:
            path.unlink()
            removed.append(path)
            log.info("%s: removed the reserve of a take whose recording was cut off", path)
        except OSError:
            pass  # read-only medium: nothing to free
        finally:
            os.close(fd)
    return removed
