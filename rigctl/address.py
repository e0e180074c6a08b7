"""Device addresses from rig files, parsed once into a typed value.

A rig file names every device by an address: ``sim://r1c1`` and ``v4l2:///dev/video0`` (or a bare
``/dev/video0``, ``/dev/v4l/by-id/...``) for cameras; a serial port path or a pyserial URL (``loop://``,
``spy://``, ``rfc2217://``, ``socket://``), ``sim://bridge``, ``udp://HOST:PORT`` or ``tcp://HOST:PORT`` for
serial and network lines. :func:`parse_address` turns the text into an :class:`Address` whose ``scheme`` the
registry looks up in its factory tables; nothing else in the code inspects address prefixes.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from urllib.parse import parse_qsl

from rigctl.errors import DeviceError

CAMERA_SCHEMES = ("sim", "v4l2")
# pyserial's own URL handlers (serial_for_url), reached through the serial transport
PYSERIAL_SCHEMES = ("loop", "spy", "rfc2217", "socket", "alt", "hwgrep", "cp2110")
LINE_SCHEMES = ("serial", "sim", "udp", "tcp", *PYSERIAL_SCHEMES)


@dataclass(frozen=True)
class Address:
    """A parsed device address: ``scheme`` (``sim``, ``v4l2``, ``serial``, ``udp``, ``tcp``, or a pyserial handler),
    ``target`` (the camera or device name, the device path, or host:port) and ``options`` from a
    ``?key=value&...`` query. ``text`` is the address as written, for messages and for pyserial."""

    text: str
    scheme: str
    target: str
    options: dict[str, str] = field(default_factory=dict, compare=False)

    @property
    def base(self) -> str:
        """The address without its query."""
        return self.text.partition("?")[0]

    @property
    def is_local_path(self) -> bool:
        """A node under /dev (or another file path) that exists or not on this machine."""
        return self.scheme in ("v4l2", "serial")

    def exists(self) -> bool:
        return os.path.exists(self.target) if self.is_local_path else True

    def __str__(self) -> str:
        return self.text


def _split(text: str) -> tuple[str, str, dict[str, str]]:
    base, _, query = text.partition("?")
    options = dict(parse_qsl(query, keep_blank_values=True)) if query else {}
    if "://" in base:
        scheme, _, rest = base.partition("://")
        return scheme.lower(), rest, options
    return "", base, options


def parse_address(text: str, role: str, schemes: tuple[str, ...]) -> Address:
    """Parse ``text`` for a device of ``role`` (e.g. "camera r0c0", "tally port"), accepting ``schemes``.

    Raises DeviceError naming the role, the address and the schemes accepted."""
    if not isinstance(text, str) or not text.strip():
        raise DeviceError(f"{role}: empty device address")
    if "\x00" in text:  # no path holds one: os refuses it with a ValueError, not as a missing device
        raise DeviceError(f"{role}: device address {text!r}: holds a NUL character")
    scheme, rest, options = _split(text.strip())
    if scheme == "" and rest.startswith("/"):
        # a bare path: a V4L2 node for cameras, a serial port for lines
        scheme = "v4l2" if rest.startswith(("/dev/video", "/dev/v4l/")) and "v4l2" in schemes else "serial"
    if scheme not in schemes:
        accepted = ", ".join(f"{s}://" if s != "serial" else "a serial port path" for s in schemes)
        raise DeviceError(f"{role}: device address {text!r}: unknown scheme (accepted: {accepted})")
    if scheme == "v4l2" and not rest.startswith("/"):
        raise DeviceError(f"{role}: device address {text!r}: expected v4l2:///dev/videoN (an absolute path)")
    if not rest and scheme not in PYSERIAL_SCHEMES:  # loop:// needs no target
        raise DeviceError(f"{role}: device address {text!r} names no device")
    return Address(text=text.strip(), scheme=scheme, target=rest, options=options)


def camera_address(text: str, camera: str) -> Address:
    """The address of ``camera``; a simulated one is ``sim://`` and the camera's own name (the simulator makes
    the rig's cameras, nothing else: a path or another camera's name is refused, as recording refuses it)."""
    address = parse_address(text, f"camera {camera}", CAMERA_SCHEMES)
    if address.scheme == "sim" and address.target != camera:
        raise DeviceError(f"camera {camera}: device address {text!r}: a simulated camera is sim://{camera}")
    return address


def line_address(text: str, role: str) -> Address:
    """The address of a serial or network line; the one simulated line is the SDI bridge, ``sim://bridge``."""
    address = parse_address(text, role, LINE_SCHEMES)
    if address.scheme == "sim" and address.target != "bridge":
        raise DeviceError(f"{role}: device address {text!r}: the simulated line is sim://bridge")
    return address
