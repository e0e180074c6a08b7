"""USB identities: the real pyusb code path on a simulated backend; none or several matches are errors
naming the identity."""

from __future__ import annotations

import pytest
from rigctl.drivers.usb_identity import list_usb, resolve
from rigctl.simulators.usb_backend import SimUsbBackend, SimUsbDevice

from rigctl.errors import DeviceError
from rigctl.rig import UsbIdentity

FTDI = (0x0403, 0x6001)


def backend() -> SimUsbBackend:
    return SimUsbBackend(
        [
            SimUsbDevice(*FTDI, serial="A10KX3", manufacturer="FTDI", product="FT232R USB UART", bus=1, ports=(2, 1)),
            SimUsbDevice(*FTDI, serial="A10KX4", manufacturer="FTDI", product="FT232R USB UART", bus=1, ports=(2, 2)),
            SimUsbDevice(0x1EDB, 0xBE55, serial=None, product="UltraStudio", bus=2, ports=(1,)),
        ]
    )


def test_enumeration_reads_strings_through_pyusb() -> None:
    b = backend()
    devices = list_usb(b)
    assert [d.serial for d in devices] == ["A10KX3", "A10KX4", None]
    assert devices[0].bus_path == "1-2.1" and devices[0].product == "FT232R USB UART"
    assert devices[2].vendor_id == 0x1EDB and devices[2].product == "UltraStudio"
    assert b.opened >= 2  # string descriptors were really requested from the devices


def test_resolution_by_serial_and_by_bus_path() -> None:
    devices = list_usb(backend())
    got = resolve(
        {
            "tally": UsbIdentity(vendor_id=FTDI[0], product_id=FTDI[1], serial="A10KX4"),
            "bridge": UsbIdentity(vendor_id=FTDI[0], product_id=FTDI[1], bus_path="1-2.1"),
        },
        devices,
    )
    assert got["tally"].bus_path == "1-2.2" and got["bridge"].serial == "A10KX3"


def test_ambiguous_and_missing_identities_are_named() -> None:
    devices = list_usb(backend())
    with pytest.raises(DeviceError, match=r"tally: 2 attached USB devices match 0403:6001 .*add serial or bus_path"):
        resolve({"tally": UsbIdentity(vendor_id=FTDI[0], product_id=FTDI[1])}, devices)
    with pytest.raises(DeviceError, match=r"bridge: no attached USB device matches 0403:6001 serial NOPE"):
        resolve({"bridge": UsbIdentity(vendor_id=FTDI[0], product_id=FTDI[1], serial="NOPE")}, devices)
