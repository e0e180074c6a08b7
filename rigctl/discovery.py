"""What is attached to this machine (V4L2 nodes, serial ports, USB identities), and how it maps onto a rig:
the ``rigctl devices`` report. Nothing here opens a device for capture or control."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any, NotRequired, TypedDict

from rigctl.address import camera_address, line_address
from rigctl.errors import DeviceError, RigFileError
from rigctl.publish import kind
from rigctl.rig import Rig, UsbIdentity


class V4L2Node(TypedDict):
    path: str
    driver: str
    card: str
    bus: str
    formats: list[str]
    signal: str
    aliases: list[str]  # /dev/v4l/by-path and by-id links to it
    error: str  # "" when the node answered


class SerialPort(TypedDict):
    device: str
    description: str
    usb: str | None  # vendor:product when it is a USB adapter
    serial: str | None
    location: str | None


class UsbEntry(TypedDict, total=False):
    """An attached USB device, or the one error that stopped the listing."""

    describe: str
    vendor_id: int
    product_id: int
    serial: str | None
    bus_path: str
    manufacturer: str | None
    product: str | None
    error: str


class CameraDiscovery(TypedDict):
    name: str
    device: str
    state: str  # "found", "MISSING" or "simulated"
    resolved: NotRequired[str]  # the device node the address resolves to


class LineState(TypedDict):
    role: str  # "tally" or "bridge"
    address: str
    state: str  # "found", "MISSING", "network" or "simulated"


class IdentityState(TypedDict):
    role: str
    state: str  # "found" or "PROBLEM"
    device: NotRequired[str]
    error: NotRequired[str]


class AttachedReport(TypedDict):
    """The ``rigctl devices`` report (``--json`` prints it as it is)."""

    v4l2: list[V4L2Node]
    serial: list[SerialPort]
    usb: list[UsbEntry]
    cameras: list[CameraDiscovery]
    lines: list[LineState]
    usb_identities: list[IdentityState]
    missing: list[str]


def usb_backend() -> Any:
    """The pyusb backend to enumerate with: libusb, or the simulated backend when ``RIGCTL_SIM_USB`` names a
    YAML list of simulated devices (vendor_id, product_id, serial, manufacturer, product, bus, ports)."""
    path = os.environ.get("RIGCTL_SIM_USB")
    if not path:
        return None
    from rigctl.simulators.usb_backend import load_sim_usb

    return load_sim_usb(Path(path))


def _serial_ports() -> list[SerialPort]:
    from serial.tools import list_ports

    out: list[SerialPort] = []
    for port in list_ports.comports():
        out.append(
            {
                "device": port.device,
                "description": port.description,
                "usb": f"{port.vid:04x}:{port.pid:04x}" if port.vid is not None and port.pid is not None else None,
                "serial": port.serial_number,
                "location": port.location,
            }
        )
    return out


def rig_usb_identities(rig: Rig) -> dict[str, UsbIdentity]:
    """Every USB identity the rig file names, keyed by what it identifies (camera r0c0, tally, bridge)."""
    out: dict[str, UsbIdentity] = {f"camera {c.name}": c.usb for c in rig.model.cameras if c.usb is not None}
    if rig.model.tally is not None and rig.model.tally.usb is not None:
        out["tally"] = rig.model.tally.usb
    if rig.model.camera_control is not None and rig.model.camera_control.usb is not None:
        out["bridge"] = rig.model.camera_control.usb
    return out


def _line_state(text: str, role: str) -> str:
    address = line_address(text, role)
    if address.scheme == "sim":
        return "simulated"
    if not address.is_local_path:
        return "network"
    return "found" if _not_a_device(address.target) is None else "MISSING"


def _tally_url_problem(rig: Rig, url: str) -> str | None:
    """Why a network tally address is one ``rigctl tally`` refuses before it sends (not a TSL 5.0 URL, no
    port, a host name no resolver takes), or None; whether a receiver answers there is not tried."""
    if rig.model.tally is None or rig.model.tally.protocol != "tsl-umd-5.0":
        return None
    from rigctl.drivers.tsl50_output import parse_url

    try:
        _, host, _ = parse_url(url)
        host.encode("idna")  # what the resolver does first ('a..b', an empty label, a label of 64+)
    except RigFileError as exc:
        return str(exc)
    except UnicodeError:
        return f"{url}: {host!r:.80} is not a host name"
    return None


def _not_a_device(path: str) -> str | None:
    """Why a line's ``path`` is no device node (missing, or a folder, file, FIFO or socket: rigctl tally refuses
    those), or None when it is one."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return "no such device"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return None
    return f"exists but is {kind(mode)}, not a device"


def describe_attached(rig: Rig) -> AttachedReport:
    """Attached devices of every kind the rig uses, and each of the rig's devices: found, missing or simulated."""
    addresses = {c.name: camera_address(c.device, c.name) for c in rig.cameras}
    v4l2: list[V4L2Node] = []
    if any(a.scheme == "v4l2" for a in addresses.values()) or any(p.startswith("video") for p in os.listdir("/dev")):
        from rigctl.drivers.v4l2.discovery import list_v4l2

        v4l2 = [
            V4L2Node(
                path=d.path,
                driver=d.driver,
                card=d.card,
                bus=d.bus,
                formats=d.formats,
                signal=d.signal,
                aliases=d.aliases,
                error=d.error,
            )
            for d in list_v4l2()
        ]
    known = {d["path"] for d in v4l2}
    cams: list[CameraDiscovery] = []
    missing: list[str] = []
    for cam in rig.cameras:
        if addresses[cam.name].scheme == "sim":
            entry = CameraDiscovery(name=cam.name, device=cam.device, state="simulated")
        else:
            resolved = os.path.realpath(addresses[cam.name].target)
            state = "found" if resolved in known else "MISSING"
            entry = CameraDiscovery(name=cam.name, device=cam.device, resolved=resolved, state=state)
            if resolved not in known:
                missing.append(f"{cam.name} ({cam.device})")
        cams.append(entry)
    lines: list[LineState] = []
    for role, address in (
        ("tally", rig.model.tally.port if rig.model.tally else None),
        ("bridge", rig.model.camera_control.bridge if rig.model.camera_control else None),
    ):
        if address is None:
            continue
        state = _line_state(address, f"{role} line")
        if state == "network" and role == "tally" and (why := _tally_url_problem(rig, address)):
            state = "INVALID"
            missing.append(f"tally line ({why})")
        lines.append({"role": role, "address": address, "state": state})
        if state == "MISSING":
            why = _not_a_device(line_address(address, f"{role} line").target)
            missing.append(f"{role} line ({address}{'' if why == 'no such device' else f': {why}'})")
    usb: list[UsbEntry] = []
    identities: list[IdentityState] = []
    wanted = rig_usb_identities(rig)
    try:
        from rigctl.drivers.usb_identity import list_usb, resolve

        attached = list_usb(usb_backend())
        usb = [
            UsbEntry(
                describe=d.describe(),
                vendor_id=d.vendor_id,
                product_id=d.product_id,
                serial=d.serial,
                bus_path=d.bus_path,
                manufacturer=d.manufacturer,
                product=d.product,
            )
            for d in attached
        ]
        for role, ident in wanted.items():
            try:
                dev = resolve({role: ident}, attached)[role]
                identities.append({"role": role, "state": "found", "device": dev.describe()})
            except DeviceError as exc:
                identities.append({"role": role, "state": "PROBLEM", "error": str(exc)})
                missing.append(str(exc))
    except DeviceError as exc:
        if wanted:
            missing.append(str(exc))
        usb = [{"error": str(exc)}]
    return {
        "v4l2": v4l2,
        "serial": _serial_ports(),
        "usb": usb,
        "cameras": cams,
        "lines": lines,
        "usb_identities": identities,
        "missing": missing,
    }
