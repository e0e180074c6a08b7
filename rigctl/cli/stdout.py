"""rigctl's stdout behind a guard, installed by :func:`rigctl.cli.main.main` around every verb.

A verb prints with ``print`` or a ``rich`` console, both through ``sys.stdout``; writing it can fail in ways
no verb should have to handle: a full device (``> /dev/full``, a full disk), an I/O error (a terminal that went
away), a stdout that was closed (``>&-``). The guard turns each into one :class:`StdoutError` (exit 4, the
destination) naming what stdout is, and points file descriptor 1 at ``/dev/null`` so the interpreter's last
flush cannot report the same failure again as a traceback. A reader that went away (``| head -1``) stays a
:class:`BrokenPipeError`, which ``main`` ends quietly.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Iterable
from typing import Any, TextIO

from rigctl.errors import OutputError


class StdoutError(OutputError):
    """Standard output cannot be written: full, failing or closed."""


def _what(fd: int) -> str:
    """``stdout`` and, where the system says, what it is (``stdout (/dev/full)``)."""
    try:
        target = os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        return "stdout"
    return f"stdout ({target})"


def to_devnull(fd: int) -> None:
    """Whatever is still buffered for ``fd`` goes nowhere, quietly (a closed pipe, a failed stdout)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    if devnull == fd:  # ``fd`` was closed: /dev/null took its number
        return
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)


def _error(stream: Any, exc: OSError) -> StdoutError:
    try:
        fd = stream.fileno()
    except (OSError, ValueError, AttributeError):
        fd = None
    what = "stdout" if fd is None else _what(fd)
    if fd is not None:
        to_devnull(fd)
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        reason = "no space left on the device"
    elif exc.errno == errno.EBADF:
        reason = "not open for writing"
    else:
        reason = exc.strerror or str(exc)
    return StdoutError(f"{what}: cannot write the output: {reason}")


class GuardedStdout:
    """A text stream that writes through ``stream`` and reports its failures as :class:`StdoutError`; every
    other attribute (``fileno``, ``isatty``, ``encoding``, ``buffer``) is the stream's own."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        if not text:  # rich writes "" when it ends a capture: not output, and /dev/full refuses even that
            return 0
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise _error(self._stream, exc) from None

    def writelines(self, lines: Iterable[str]) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise _error(self._stream, exc) from None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


class ClosedStdout:
    """What stands for a stdout that was closed before rigctl started: a verb that prints nothing succeeds,
    one that prints ends in one line."""

    encoding = "utf-8"
    errors = "strict"

    def write(self, text: str) -> int:
        if not text:
            return 0
        raise StdoutError("stdout is closed: cannot write the output (run without >&-, or send it to /dev/null)")

    def writelines(self, lines: Iterable[str]) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False

    def fileno(self) -> int:
        raise OSError(errno.EBADF, "stdout is closed")


def guard(stream: TextIO | None) -> TextIO:
    """The guard for ``stream`` (``sys.stdout``). A closed stdout (None) also gets ``/dev/null`` on descriptor 1,
    so the next file rigctl opens cannot take its number and receive what a library prints."""
    if stream is None:
        try:
            os.fstat(1)
        except OSError:
            to_devnull(1)
        return ClosedStdout()  # type: ignore[return-value]
    return GuardedStdout(stream)  # type: ignore[return-value]
