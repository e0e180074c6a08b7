"""Reading a file received from someone else: a regular file only, checked on the open descriptor (a path can
be swapped for a FIFO or ``/dev/zero`` between a ``stat`` and an ``open``), its size bounded before a byte is
read. The open does not block on a FIFO (``O_NONBLOCK``) and never takes a terminal (``O_NOCTTY``)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from rigctl.errors import RigctlError, TakeError


def open_regular(path: Path, error: type[RigctlError] = TakeError, what: str = "file") -> tuple[int, int]:
    """An open descriptor of ``path`` (read-only) and its size; refuses anything but a regular file."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC)
    except FileNotFoundError:
        try:
            target = os.readlink(path)  # there is something at the name: a link that leads to no file
        except OSError:
            raise error(f"{path}: no such {what}") from None
        raise error(f"{path}: {what} is a symbolic link to {target!r:.200}, which leads to no file") from None
    except OSError as exc:
        raise error(f"{path}: cannot open {what}: {exc.strerror}") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a device, pipe or socket)"
        raise error(f"{path}: {what} is {kind}: refused")
    # O_NONBLOCK was for the open alone: left on a regular file it makes some filesystems (9p, as a VM's shared
    # folder) answer each read with one message's worth of bytes, so a frame read short
    os.set_blocking(fd, True)
    return fd, st.st_size


def read_regular(path: Path, limit: int, error: type[RigctlError] = TakeError, what: str = "file") -> bytes:
    """The bytes of the regular file ``path``, refused in one line if it holds more than ``limit`` bytes."""
    fd, size = open_regular(path, error, what)
    try:
        if size > limit:
            raise error(f"{path}: {what} of {size:,} bytes is over the limit of {limit:,} bytes")
        chunks, got = [], 0
        while got <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - got))
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        if got > limit:  # it grew while we read
            raise error(f"{path}: {what} grew past the limit of {limit:,} bytes while being read")
        return b"".join(chunks)
    except OSError as exc:
        raise error(f"{path}: cannot read {what}: {exc.strerror}") from None
    finally:
        os.close(fd)
