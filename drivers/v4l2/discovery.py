"""What V4L2 capture devices are attached, for ``rigctl devices``."""

from __future__ import annotations

import glob
import logging
import os
from dataclasses import dataclass, field

from rigctl.drivers.v4l2.device import V4L2Device

from rigctl.errors import DeviceError

log = logging.getLogger(__name__)


@dataclass
class V4L2Info:
    path: str
    driver: str = ""
    card: str = ""
    bus: str = ""
    formats: list[str] = field(default_factory=list)
    signal: str = ""
    aliases: list[str] = field(default_factory=list)  # /dev/v4l/by-path and by-id links to it
    error: str = ""


def _aliases() -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for link in glob.glob("/dev/v4l/by-path/*") + glob.glob("/dev/v4l/by-id/*"):
        out.setdefault(os.path.realpath(link), []).append(link)
    return out


def list_v4l2() -> list[V4L2Info]:
    """Every /dev/videoN that is a capture device, with what it offers and what its input receives."""
    aliases = _aliases()
    found = []
    for path in sorted(glob.glob("/dev/video*"), key=lambda p: (len(p), p)):
        info = V4L2Info(path=path, aliases=aliases.get(os.path.realpath(path), []))
        dev = V4L2Device(path)
        try:
            dev.open()
        except DeviceError as exc:
            if "not a streaming video capture device" in str(exc):
                log.debug("%s: skipped: %s", path, exc)
                continue
            info.error = str(exc)
            found.append(info)
            continue
        try:
            ident = dev.identity()
            info.driver, info.card, info.bus = ident["driver"], ident["card"], ident["bus"]
            info.formats = dev.formats()
            if dev.has_dv_timings():
                t = dev.query_dv_timings()
                info.signal = "no signal" if t is None else t.describe()
            else:
                w, h, fourcc, _ = dev.get_format()
                info.signal = f"{w}x{h} {fourcc} {dev.get_rate():g} fps"
        except DeviceError as exc:
            info.error = str(exc)
        finally:
            dev.close()
        found.append(info)
    return found
