"""Serial transports addressed by URL: a real port (/dev/ttyUSB0), a pseudo-terminal, or pyserial's
``loop://`` and ``spy://`` handlers, opened exclusively with the protocol's line settings."""

from __future__ import annotations

from typing import Any

import serial

from rigctl.errors import DeviceError


def open_link(url: str, settings: dict[str, Any], timeout_s: float = 1.0) -> serial.SerialBase:
    """Open ``url`` with ``settings`` (baudrate, bytesize, parity, stopbits); exclusive for real ports, so two
    processes cannot drive the same line."""
    kwargs = dict(settings)
    kwargs.update(timeout=timeout_s, write_timeout=timeout_s)
    if "://" not in url:
        kwargs["exclusive"] = True
    try:
        return serial.serial_for_url(url, **kwargs)
    except serial.SerialException as exc:
        text = str(exc)
        if "Resource temporarily unavailable" in text or "exclusively lock" in text:
            raise DeviceError(f"{url}: port is busy (another process drives this line)") from None
        if "No such file" in text or "could not open port" in text:
            raise DeviceError(f"{url}: no such serial port") from None
        raise DeviceError(f"{url}: cannot open serial port: {text}") from None
