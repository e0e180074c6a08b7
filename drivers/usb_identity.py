"""USB identity of attached devices (capture dongles, USB-serial adapters) with pyusb, and matching the
identities in a rig file, so a rig resolves to the same physical devices after every reboot."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import usb.core
import usb.util

from rigctl.errors import DeviceError
from rigctl.rig import UsbIdentity

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class UsbDevice:
    vendor_id: int
    product_id: int
    serial: str | None
    bus_path: str
    manufacturer: str | None = None
    product: str | None = None

    def describe(self) -> str:
        name = " ".join(p for p in (self.manufacturer, self.product) if p) or "?"
        return f"{self.vendor_id:04x}:{self.product_id:04x} {name} serial {self.serial or '-'} at {self.bus_path}"


def _string(dev: Any, attr: str) -> str | None:
    try:
        value = getattr(dev, attr)
    except (ValueError, NotImplementedError, usb.core.USBError) as exc:
        log.debug("USB %s: %s unreadable: %s", getattr(dev, "address", "?"), attr, exc)
        return None  # no permission to open the device, or no string descriptors
    return str(value) if value else None


def list_usb(backend: Any = None) -> list[UsbDevice]:
    """Every attached USB device, with its serial number and bus path (``bus-port.port``)."""
    try:
        found = list(usb.core.find(find_all=True, backend=backend) or [])
    except usb.core.NoBackendError:
        raise DeviceError("USB: no libusb backend on this host (install libusb-1.0)") from None
    out = []
    for dev in found:
        ports = ".".join(str(p) for p in (dev.port_numbers or ()))
        out.append(
            UsbDevice(
                int(dev.idVendor),
                int(dev.idProduct),
                _string(dev, "serial_number"),
                f"{dev.bus}-{ports}" if ports else str(dev.bus),
                _string(dev, "manufacturer"),
                _string(dev, "product"),
            )
        )
    return out


def _matches(ident: UsbIdentity, dev: UsbDevice) -> bool:
    return (
        dev.vendor_id == ident.vendor_id
        and dev.product_id == ident.product_id
        and (ident.serial is None or dev.serial == ident.serial)
        and (ident.bus_path is None or dev.bus_path == ident.bus_path)
    )


def resolve(identities: dict[str, UsbIdentity], devices: list[UsbDevice]) -> dict[str, UsbDevice]:
    """Each named identity's one attached device; a clear error naming the identity when none or several match."""
    out = {}
    for name, ident in identities.items():
        want = (
            f"{ident.vendor_id:04x}:{ident.product_id:04x}"
            + (f" serial {ident.serial}" if ident.serial else "")
            + (f" at {ident.bus_path}" if ident.bus_path else "")
        )
        hits = [d for d in devices if _matches(ident, d)]
        if not hits:
            raise DeviceError(f"{name}: no attached USB device matches {want}")
        if len(hits) > 1:
            raise DeviceError(
                f"{name}: {len(hits)} attached USB devices match {want} ("
                + "; ".join(h.describe() for h in hits)
                + "): add serial or bus_path to the rig file's usb identity"
            )
        out[name] = hits[0]
    return out
