"""Serial transports addressed by URL: a real port (/dev/ttyUSB0), a pseudo-terminal, or pyserial's
``loop://`` and ``spy://`` handlers, opened exclusively with the protocol's line settings.

Every way opening can fail (unknown URL scheme, missing node, busy line, a node that is not a terminal,
settings the driver refuses) becomes a :class:`~rigctl.errors.DeviceError` naming the port.
"""

from __future__ import annotations

import errno
import logging
import os
import stat
import termios
from typing import Any

import serial

from rigctl.errors import DeviceError

log = logging.getLogger(__name__)

# Linux Unix98 pseudo-terminal slaves (/dev/pts/N) have majors 136-143.
_PTY_MAJORS = range(136, 144)


def _is_pty(url: str) -> bool:
    try:
        return os.major(os.stat(url).st_rdev) in _PTY_MAJORS
    except (OSError, ValueError):
        return False


def _open(url: str, kwargs: dict[str, Any]) -> serial.SerialBase:
    try:
        return serial.serial_for_url(url, **kwargs)
    except termios.error as exc:
        parity = kwargs.get("parity", serial.PARITY_NONE)
        if exc.args and exc.args[0] == errno.EINVAL and parity != serial.PARITY_NONE and _is_pty(url):
            # A pty has no parity: the kernel clears PARENB, and glibc's tcsetattr then reports EINVAL when a
            # line already configured with parity is opened again. Open it without parity and record the
            # protocol's parity on the port object, which is all a pty can carry.
            log.debug("%s: pseudo-terminal refuses parity %s on re-open; opened without", url, parity)
            link = serial.serial_for_url(url, **{**kwargs, "parity": serial.PARITY_NONE})
            link._parity = parity  # not applied to a pty, see above
            return link
        raise DeviceError(f"{url}: the port refuses the line settings {_settings(kwargs)}: {exc.args[-1]}") from None


def _settings(kwargs: dict[str, Any]) -> str:
    return (
        f"{kwargs.get('baudrate', 9600)} {kwargs.get('bytesize', 8)}{kwargs.get('parity', 'N')}"
        f"{kwargs.get('stopbits', 1)}"
    )


def _not_a_device(path: str) -> str | None:
    """Why ``path`` cannot be a serial port when it plainly is none (missing, a folder, a file, a FIFO, a
    socket); None for a device node, whose own error says more."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "no such serial port"
    except OSError:
        return None
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return None
    what = (
        "a folder"
        if stat.S_ISDIR(mode)
        else "a FIFO"
        if stat.S_ISFIFO(mode)
        else ("a socket" if stat.S_ISSOCK(mode) else "a regular file")
    )
    return f"exists but is {what}, not a serial port (give a device such as /dev/ttyUSB0)"


def open_link(url: str, settings: dict[str, Any], timeout_s: float = 1.0) -> serial.SerialBase:
    """Open ``url`` with ``settings`` (baudrate, bytesize, parity, stopbits); exclusive for real ports, so two
    processes cannot drive the same line."""
    kwargs = dict(settings)
    kwargs.update(timeout=timeout_s, write_timeout=timeout_s)
    if "://" not in url:
        kwargs["exclusive"] = True
    try:
        return _open(url, kwargs)
    except serial.SerialException as exc:
        text = str(exc)
        if "://" not in url and (problem := _not_a_device(url)):
            raise DeviceError(f"{url}: {problem}") from None
        if "Resource temporarily unavailable" in text or "exclusively lock" in text:
            raise DeviceError(f"{url}: port is busy (another process drives this line)") from None
        if "No such file" in text or "could not open port" in text:
            raise DeviceError(f"{url}: no such serial port") from None
        if "Inappropriate ioctl" in text:
            raise DeviceError(f"{url}: not a serial port (not a terminal device)") from None
        raise DeviceError(f"{url}: cannot open serial port: {text}") from None
    except ValueError as exc:  # pyserial: unknown URL scheme, or a setting out of its range
        raise DeviceError(f"{url}: cannot open serial port: {exc}") from None
    except (OSError, termios.error) as exc:
        raise DeviceError(f"{url}: cannot open serial port: {exc}") from None
