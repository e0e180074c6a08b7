"""A simulated pyusb backend: USB devices described as data, served through pyusb's backend interface,
so tests run the real pyusb code path (device enumeration, descriptors, string requests)."""

from __future__ import annotations

import array
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import usb.backend
import yaml

_GET_DESCRIPTOR = 6
_STRING = 3
_LANGID_EN_US = 0x0409


@dataclass
class SimUsbDevice:
    vendor_id: int
    product_id: int
    serial: str | None = None
    manufacturer: str | None = None
    product: str | None = None
    bus: int = 1
    ports: tuple[int, ...] = (1,)
    address: int = 2


class _Descriptor:
    def __init__(self, dev: SimUsbDevice) -> None:
        self.bLength, self.bDescriptorType, self.bcdUSB = 18, 1, 0x0200
        self.bDeviceClass = self.bDeviceSubClass = self.bDeviceProtocol = 0
        self.bMaxPacketSize0 = 64
        self.idVendor, self.idProduct, self.bcdDevice = dev.vendor_id, dev.product_id, 0x0100
        self.iManufacturer = 1 if dev.manufacturer else 0
        self.iProduct = 2 if dev.product else 0
        self.iSerialNumber = 3 if dev.serial else 0
        self.bNumConfigurations = 1
        self.address, self.bus = dev.address, dev.bus
        self.port_number = dev.ports[-1] if dev.ports else None
        self.port_numbers = dev.ports
        self.speed = 3


class SimUsbBackend(usb.backend.IBackend):
    def __init__(self, devices: list[SimUsbDevice]) -> None:
        self.devices = devices
        self.opened = 0

    def enumerate_devices(self) -> list[SimUsbDevice]:
        return list(self.devices)

    def get_device_descriptor(self, dev: SimUsbDevice) -> _Descriptor:
        return _Descriptor(dev)

    def open_device(self, dev: SimUsbDevice) -> SimUsbDevice:
        self.opened += 1
        return dev

    def close_device(self, dev_handle: SimUsbDevice) -> None:
        return None

    def ctrl_transfer(
        self,
        dev_handle: SimUsbDevice,
        bmRequestType: int,
        bRequest: int,
        wValue: int,
        wIndex: int,
        data: Any,
        timeout: int,
    ) -> int:
        if bRequest != _GET_DESCRIPTOR or wValue >> 8 != _STRING:
            raise usb.core.USBError("request not supported by the simulated device", errno=32)
        index = wValue & 0xFF
        if index == 0:
            payload = bytes([4, _STRING]) + _LANGID_EN_US.to_bytes(2, "little")
        else:
            text = {1: dev_handle.manufacturer, 2: dev_handle.product, 3: dev_handle.serial}.get(index)
            if text is None:
                raise usb.core.USBError("no such string", errno=32)
            raw = text.encode("utf-16-le")
            payload = bytes([2 + len(raw), _STRING]) + raw
        n = min(len(payload), len(data))
        data[:n] = array.array("B", payload[:n])
        return n


def load_sim_usb(path: Path) -> SimUsbBackend:
    """Simulated devices from a YAML list (for ``RIGCTL_SIM_USB``); errors name the file and entry."""
    from rigctl.errors import ParameterError

    try:
        items = yaml.safe_load(path.read_text(encoding="utf-8")) or []
    except (OSError, yaml.YAMLError) as exc:
        raise ParameterError(f"{path}: cannot read simulated USB devices: {exc}") from None
    if not isinstance(items, list):
        raise ParameterError(f"{path}: expected a list of simulated USB devices")
    devices = []
    for i, item in enumerate(items):
        try:
            if "ports" in item:
                item = {**item, "ports": tuple(item["ports"])}
            devices.append(SimUsbDevice(**item))
        except TypeError as exc:
            raise ParameterError(f"{path}: entry {i}: {exc}") from None
    return SimUsbBackend(devices)
