"""The one place that maps a rig file's device addresses onto drivers and simulators.

``sim://rXcY`` cameras come from :mod:`rigctl.simulators`; ``v4l2:///dev/videoN`` (and the stable
``/dev/v4l/by-path/...`` and ``/dev/v4l/by-id/...`` forms) from :mod:`rigctl.drivers`. Everything above
this module sees only the interfaces in :mod:`rigctl.interfaces`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from rigctl.camera_control import ControlPath
from rigctl.errors import DeviceError, RigFileError
from rigctl.interfaces import Camera
from rigctl.rig import Rig
from rigctl.tally import TallyOutput, tsl_addresses

log = logging.getLogger(__name__)


class TruthProvider(Protocol):
    """Something that knows what the cameras really saw (only a simulation can)."""

    def write_truth(self, folder: Path, frame_sets: list[tuple[int, dict[str, int]]]) -> None:
        """Write ``truth/`` for frame sets given as (number, {camera: sequence number})."""


@dataclass
class DeviceSet:
    """The opened devices of a rig."""

    cameras: dict[str, Camera]
    truth: TruthProvider | None = None
    settings: dict[str, Any] = field(default_factory=dict)  # recorded in the take's manifest
    description: str = ""

    def close(self) -> None:
        for cam in self.cameras.values():
            try:
                cam.close()
            except Exception as exc:  # closing must reach every camera
                log.warning("closing %s: %s", cam.name, exc)


def scheme_of(address: str) -> str:
    if address.startswith("sim://"):
        return "sim"
    if address.startswith("v4l2://") or address.startswith("/dev/video") or address.startswith("/dev/v4l/"):
        return "v4l2"
    raise DeviceError(f"device address {address!r}: unknown scheme (use sim://rXcY or v4l2:///dev/videoN)")


def open_cameras(rig: Rig, sim: list[str] | None = None, cameras: list[str] | None = None) -> DeviceSet:
    """Create camera objects for ``rig`` (not yet opened). ``sim`` holds ``KEY=VALUE`` settings for
    simulated cameras; ``cameras`` limits the set to the named ones."""
    wanted = [c for c in rig.cameras if cameras is None or c.name in cameras]
    if cameras:
        unknown = set(cameras) - {c.name for c in rig.cameras}
        if unknown:
            raise DeviceError(f"rig {rig.name} has no camera {', '.join(sorted(unknown))}")
    schemes = {scheme_of(c.device) for c in wanted}
    if sim and "sim" not in schemes:
        raise DeviceError(f"--sim settings given but rig {rig.name} has no simulated cameras")
    out: dict[str, Camera] = {}
    truth: TruthProvider | None = None
    settings: dict[str, Any] = {}
    description = ""
    if "sim" in schemes:
        from rigctl.simulators.device_set import simulated_cameras

        sim_cams, truth, settings, description = simulated_cameras(rig, sim or [], [c.name for c in wanted])
        out.update(sim_cams)
    if "v4l2" in schemes:
        from rigctl.drivers.v4l2.camera import V4L2Camera

        for cam in wanted:
            if scheme_of(cam.device) == "v4l2":
                out[cam.name] = V4L2Camera(cam.name, cam.device)
    return DeviceSet(cameras=out, truth=truth, settings=settings, description=description)


def sim_settings_help() -> str:
    """The simulator's settings, for ``rigctl record --help``."""
    from rigctl.simulators.settings import describe_settings

    return describe_settings()


def usb_backend() -> Any:
    """The pyusb backend to enumerate with: libusb, or the simulated backend when ``RIGCTL_SIM_USB`` names a
    YAML list of simulated devices (vendor_id, product_id, serial, manufacturer, product, bus, ports)."""
    import os

    path = os.environ.get("RIGCTL_SIM_USB")
    if not path:
        return None
    from rigctl.simulators.usb_backend import load_sim_usb

    return load_sim_usb(Path(path))


def _serial_ports() -> list[dict[str, Any]]:
    from serial.tools import list_ports

    out = []
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


def rig_usb_identities(rig: Rig) -> dict[str, Any]:
    """Every USB identity the rig file names, keyed by what it identifies (camera r0c0, tally, bridge)."""
    out: dict[str, Any] = {f"camera {c.name}": c.usb for c in rig.model.cameras if c.usb is not None}
    if rig.model.tally is not None and rig.model.tally.usb is not None:
        out["tally"] = rig.model.tally.usb
    if rig.model.camera_control is not None and rig.model.camera_control.usb is not None:
        out["bridge"] = rig.model.camera_control.usb
    return out


def _line_state(address: str) -> str:
    import os

    if "://" in address:
        return "simulated" if address.startswith("sim://") else "network"
    return "found" if os.path.exists(address) else "MISSING"


def describe_attached(rig: Rig) -> dict[str, Any]:
    """Attached devices of every kind the rig uses, and each of the rig's devices: found, missing or simulated."""
    import os

    schemes = {c.name: scheme_of(c.device) for c in rig.cameras}
    v4l2: list[dict[str, Any]] = []
    if "v4l2" in schemes.values() or any(p.startswith("video") for p in os.listdir("/dev")):
        from rigctl.drivers.v4l2.discovery import list_v4l2

        v4l2 = [d.as_json() for d in list_v4l2()]
    known = {d["path"] for d in v4l2}
    cams, missing = [], []
    for cam in rig.cameras:
        entry: dict[str, Any] = {"name": cam.name, "device": cam.device}
        if schemes[cam.name] == "sim":
            entry["state"] = "simulated"
        else:
            path = cam.device.removeprefix("v4l2://")
            resolved = os.path.realpath(path)
            entry["resolved"] = resolved
            entry["state"] = "found" if resolved in known else "MISSING"
            if resolved not in known:
                missing.append(f"{cam.name} ({cam.device})")
        cams.append(entry)
    lines = []
    for role, address in (
        ("tally", rig.model.tally.port if rig.model.tally else None),
        ("bridge", rig.model.camera_control.bridge if rig.model.camera_control else None),
    ):
        if address is None:
            continue
        state = _line_state(address.partition("?")[0])
        lines.append({"role": role, "address": address, "state": state})
        if state == "MISSING":
            missing.append(f"{role} line ({address})")
    usb: list[dict[str, Any]] = []
    identities: list[dict[str, Any]] = []
    wanted = rig_usb_identities(rig)
    try:
        from rigctl.drivers.usb_identity import list_usb, resolve

        attached = list_usb(usb_backend())
        usb = [{"describe": d.describe(), **d.__dict__} for d in attached]
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


def open_tally(rig: Rig, devices: DeviceSet | None = None) -> TallyOutput:
    """The rig's tally output, from its ``tally:`` section."""
    tally = rig.model.tally
    if tally is None:
        raise RigFileError(f"{rig.source}: rig {rig.name} has no tally section (add tally: protocol and port)")
    if tally.protocol == "tsl-umd-3.1":
        from rigctl.drivers.tsl31_output import Tsl31Output

        return Tsl31Output(tally.port, tsl_addresses(rig), pad_with_nul=tally.pad_with_nul)
    if tally.protocol == "tsl-umd-5.0":
        from rigctl.drivers.tsl50_output import Tsl50Output

        return Tsl50Output(tally.port, tsl_addresses(rig))
    from rigctl.camera_control import camera_ids
    from rigctl.drivers.embedded_tally_output import EmbeddedTallyOutput

    ids = camera_ids(rig) if rig.model.camera_control else {n: i + 1 for i, n in enumerate(rig.camera_names)}
    return EmbeddedTallyOutput(open_bridge(rig, tally.port, devices), ids)


def _bridge_url(url: str) -> tuple[str, dict[str, str]]:
    base, _, query = url.partition("?")
    opts = dict(part.partition("=")[::2] for part in query.split("&") if part)
    return base, opts


def open_bridge(rig: Rig, url: str, devices: DeviceSet | None = None) -> Any:
    """An SDI bridge (``rigctl.drivers.sdi_bridge.SdiBridge``) at ``url``. ``sim://bridge`` starts a simulated
    bridge on a pseudo-terminal in this process, applying what it is sent to ``devices``' simulated cameras;
    ``sim://bridge?blind=1`` simulates a bridge that cannot read values back."""
    from rigctl.drivers.sdi_bridge import SdiBridge

    base, opts = _bridge_url(url)
    if base != "sim://bridge":
        if base.startswith("sim://"):
            raise DeviceError(f"bridge address {url!r}: the simulated bridge is sim://bridge")
        return SdiBridge(url)
    from rigctl.camera_control import camera_ids
    from rigctl.simulators.sdi_bridge import SimSdiBridge

    ids = camera_ids(rig) if rig.model.camera_control else {n: i + 1 for i, n in enumerate(rig.camera_names)}
    array = getattr(devices.truth, "array", None) if devices is not None else None
    sim = SimSdiBridge(array, ids, readback=opts.get("blind", "0") in ("0", "false"))
    try:
        bridge = SdiBridge(sim.port)
    except DeviceError:
        sim.close()
        raise
    bridge.url = url
    bridge.on_close.append(sim.close)
    return bridge


def open_control(rig: Rig, devices: DeviceSet | None = None) -> ControlPath:
    """The rig's camera-control path, from its ``camera_control:`` section."""
    from rigctl.camera_control import camera_ids
    from rigctl.drivers.bmd_camera_control import BmdBridgeControl

    cc = rig.model.camera_control
    if cc is None:
        raise RigFileError(f"{rig.source}: rig {rig.name} has no camera_control section (add camera_control: bridge)")
    return BmdBridgeControl(open_bridge(rig, cc.bridge, devices), camera_ids(rig))


def simulated_array(rig: Rig, sim: list[str]) -> Any:
    """A simulated array (``rigctl.simulators.array.SimArray``) with ``--sim`` settings, for benchmarks and
    the demo that need the simulator's scenes and truth without recording a take."""
    from rigctl.simulators.array import SimArray
    from rigctl.simulators.settings import parse_sim_args

    return SimArray(rig, parse_sim_args(sim))


def simulated_view(take: Path, col: float, row: float) -> Any:
    """What a camera at grid position (col, row) of a simulated, motion-free take would have seen: (RGB in
    [0, 1], subject mask) from the simulator, or None when the take is not simulated. Only processing's
    callers reach the simulator, through here."""
    import yaml

    from rigctl.errors import TakeError
    from rigctl.rig import rig_from_dict
    from rigctl.simulators.array import SimArray
    from rigctl.simulators.settings import SimSettings
    from rigctl.simulators.views import virtual_view

    path = take / "truth" / "settings.yaml"
    if not path.exists():
        return None
    raw = yaml.safe_load((take / "take.yaml").read_text())
    rig = rig_from_dict(raw["rig"], str(take / "take.yaml"))
    array = SimArray(rig, SimSettings.model_validate(yaml.safe_load(path.read_text())))
    if not array.settings.ideal:
        return None  # a realistic take is rectified with an estimated calibration: no exact truth view
    if array.distinct_states != 1:
        raise TakeError(f"{path}: truth views need a take with one scene state (motion=false, not the charuco scene)")
    return virtual_view(array, 0, col, row)


def simulated_array_view(array: Any, col: float, row: float) -> Any:
    """(RGB, subject mask) of a virtual camera at grid position (col, row) of a simulated array's first
    scene state."""
    from rigctl.simulators.views import virtual_view

    return virtual_view(array, 0, col, row)


def simulated_burnin_box(take: Path, width: int) -> tuple[int, int, int, int] | None:
    """(y0, y1, x0, x1) around the frame id a simulated take burns into every frame (it differs between
    cameras by design, so image comparisons leave it out); None for takes that are not simulated."""
    from rigctl.simulators.burnin import block_px

    if not (take / "truth" / "settings.yaml").exists():
        return None
    b = block_px(width)
    return 0, 3 * b + 6, 0, 34 * b + 8  # two rows of 32 blocks, with room for the rectification's warp
