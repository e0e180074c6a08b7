"""The one place that maps a rig file's device addresses onto drivers and simulators.

Each address is parsed once (:mod:`rigctl.address`) and its scheme looked up in a factory table per
interface: ``sim://rXcY`` cameras come from :mod:`rigctl.simulators`, ``v4l2:///dev/videoN`` (and the stable
``/dev/v4l/by-path/...`` and ``/dev/v4l/by-id/...`` forms) from :mod:`rigctl.drivers`. Everything above
this module sees only the interfaces in :mod:`rigctl.interfaces`. What is attached to the machine is
described by :mod:`rigctl.discovery`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from rigctl.address import Address, camera_address, line_address
from rigctl.errors import DeviceError, RigFileError
from rigctl.interfaces import Camera, CameraControl, SimulatedArray, TallyOutput, TruthProvider
from rigctl.rig import Rig
from rigctl.tally import tsl_addresses

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from rigctl.drivers.sdi_bridge import SdiBridge

log = logging.getLogger(__name__)


@dataclass
class DeviceSet:
    """The devices of a rig. ``simulation`` is the simulated array behind ``sim://`` cameras (None on a
    real rig): simulated serial devices (the SDI bridge) act on it, so it is handed to them explicitly.
    ``paced``: the cameras deliver every frame when read, on a simulated clock (``--sim deterministic=true``),
    so the recorder waits for them instead of keeping pace with them."""

    cameras: dict[str, Camera]
    truth: TruthProvider | None = None
    settings: dict[str, object] = field(default_factory=dict)  # the simulator's, recorded in the take's manifest
    description: str = ""
    simulation: SimulatedArray | None = None
    paced: bool = False

    def close(self) -> None:
        for cam in self.cameras.values():
            try:
                cam.close()
            except Exception as exc:  # closing must reach every camera
                log.warning("closing %s: %s", cam.name, exc)
        if self.simulation is not None:  # its background rendering stopped and waited for before the process exits
            self.simulation.close()


def camera_addresses(rig: Rig) -> dict[str, Address]:
    """Every camera's address, parsed (DeviceError naming the camera for an address no driver takes)."""
    return {c.name: camera_address(c.device, c.name) for c in rig.cameras}


def _sim_cameras(rig: Rig, addresses: dict[str, Address], sim: list[str]) -> DeviceSet:
    from rigctl.simulators.device_set import simulated_cameras

    cams, truth, settings, description = simulated_cameras(rig, sim, addresses)
    paced = bool(settings.get("deterministic"))
    return DeviceSet(cams, truth, settings, description, simulation=truth.array, paced=paced)


def _v4l2_cameras(rig: Rig, addresses: dict[str, Address], sim: list[str]) -> DeviceSet:
    from rigctl.drivers.v4l2.camera import V4L2Camera

    return DeviceSet({name: V4L2Camera(name, a.text) for name, a in addresses.items()})


# scheme -> factory of the cameras of that scheme (given together: simulated cameras share one array)
CAMERA_FACTORIES: dict[str, Callable[[Rig, dict[str, Address], list[str]], DeviceSet]] = {
    "sim": _sim_cameras,
    "v4l2": _v4l2_cameras,
}


def open_cameras(rig: Rig, sim: list[str] | None = None, cameras: list[str] | None = None) -> DeviceSet:
    """Create camera objects for ``rig`` (not yet opened). ``sim`` holds ``KEY=VALUE`` settings for
    simulated cameras; ``cameras`` limits the set to the named ones."""
    if cameras:
        unknown = set(cameras) - set(rig.camera_names)
        if unknown:
            raise DeviceError(f"rig {rig.name} has no camera {', '.join(sorted(unknown))}")
    addresses = {n: a for n, a in camera_addresses(rig).items() if cameras is None or n in cameras}
    by_scheme: dict[str, dict[str, Address]] = {}
    for name, address in addresses.items():
        by_scheme.setdefault(address.scheme, {})[name] = address
    if sim and "sim" not in by_scheme:
        raise DeviceError(f"--sim settings given but rig {rig.name} has no simulated cameras")
    out = DeviceSet(cameras={})
    for scheme, group in by_scheme.items():
        part = CAMERA_FACTORIES[scheme](rig, group, sim or [])
        out.cameras.update(part.cameras)
        if part.truth is not None:
            out.truth, out.settings, out.description, out.simulation = (
                part.truth,
                part.settings,
                part.description,
                part.simulation,
            )
            out.paced = part.paced
    if out.paced and len(by_scheme) > 1:
        raise DeviceError(f"--sim deterministic=true: rig {rig.name} has cameras that are not simulated")
    # keep the rig's camera order whatever the schemes
    out.cameras = {n: out.cameras[n] for n in rig.camera_names if n in out.cameras}
    return out


def sim_settings_help() -> str:
    """The simulator's settings, for ``rigctl record --help``."""
    from rigctl.simulators.settings import describe_settings

    return describe_settings()


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


def open_bridge(rig: Rig, url: str, devices: DeviceSet | None = None) -> SdiBridge:
    """An SDI bridge (``rigctl.drivers.sdi_bridge.SdiBridge``) at ``url``. ``sim://bridge`` starts a simulated
    bridge on a pseudo-terminal in this process, applying what it is sent to ``devices``' simulated cameras;
    ``sim://bridge?blind=1`` simulates a bridge that cannot read values back."""
    from rigctl.drivers.sdi_bridge import SdiBridge

    address = line_address(url, "bridge")
    if address.scheme in ("udp", "tcp"):
        raise DeviceError(
            f"bridge address {url!r}: the SDI bridge is a serial line, not {address.scheme}:// "
            "(a serial line over the network is socket://HOST:PORT or rfc2217://HOST:PORT)"
        )
    if address.scheme != "sim":
        return SdiBridge(url)
    from rigctl.camera_control import camera_ids
    from rigctl.simulators.array import SimArray
    from rigctl.simulators.sdi_bridge import SimSdiBridge

    ids = camera_ids(rig) if rig.model.camera_control else {n: i + 1 for i, n in enumerate(rig.camera_names)}
    array = devices.simulation if devices is not None else None
    assert array is None or isinstance(array, SimArray)  # the only simulation there is
    sim = SimSdiBridge(array, ids, readback=address.options.get("blind", "0") in ("0", "false"))
    try:
        bridge = SdiBridge(sim.port)
    except DeviceError:
        sim.close()
        raise
    bridge.url = url
    bridge.on_close.append(sim.close)
    return bridge


def open_control(rig: Rig, devices: DeviceSet | None = None) -> CameraControl:
    """The rig's camera-control path, from its ``camera_control:`` section."""
    from rigctl.camera_control import camera_ids
    from rigctl.drivers.bmd_camera_control import BmdBridgeControl

    cc = rig.model.camera_control
    if cc is None:
        raise RigFileError(f"{rig.source}: rig {rig.name} has no camera_control section (add camera_control: bridge)")
    return BmdBridgeControl(open_bridge(rig, cc.bridge, devices), camera_ids(rig))


def simulated_array(rig: Rig, sim: list[str]) -> SimulatedArray:
    """A simulated array (``rigctl.simulators.array.SimArray``) with ``--sim`` settings, for benchmarks and
    the demo that need the simulator's scenes and truth without recording a take."""
    from rigctl.simulators.array import SimArray
    from rigctl.simulators.settings import parse_sim_args

    return SimArray(rig, parse_sim_args(sim, rig=rig))


def simulated_view(take: Path, col: float, row: float) -> tuple[NDArray[np.float32], NDArray[np.bool_]] | None:
    """What a camera at grid position (col, row) of a simulated, motion-free take would have seen: (RGB in
    [0, 1], subject mask) from the simulator, or None when the take is not simulated. Only processing's
    callers reach the simulator, through here."""

    from rigctl.errors import TakeError
    from rigctl.rig import rig_from_dict
    from rigctl.simulators.array import SimArray
    from rigctl.simulators.settings import SimSettings
    from rigctl.simulators.views import virtual_view

    path = take / "truth" / "settings.yaml"
    if not path.exists():
        return None
    from pydantic import ValidationError

    from rigctl.take.manifest import read_manifest
    from rigctl.yamlfile import load_yaml

    rig = rig_from_dict(read_manifest(take).rig, str(take / "take.yaml"))
    try:  # read with the loader's limits: a take received from someone else may carry anything here
        settings = SimSettings.model_validate(load_yaml(path))
    except ValidationError as exc:
        raise TakeError(f"{path}: not the simulator's settings ({exc.error_count()} problem(s))") from None
    array = SimArray(rig, settings)
    if not array.settings.ideal:
        return None  # a realistic take is rectified with an estimated calibration: no exact truth view
    if array.distinct_states != 1:
        raise TakeError(f"{path}: truth views need a take with one scene state (motion=false, not the charuco scene)")
    return virtual_view(array, 0, col, row)


def simulated_array_view(
    array: SimulatedArray, col: float, row: float
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """(RGB, subject mask) of a virtual camera at grid position (col, row) of a simulated array's first
    scene state."""
    from rigctl.simulators.array import SimArray
    from rigctl.simulators.views import virtual_view

    assert isinstance(array, SimArray), "an array from simulated_array()"

    return virtual_view(array, 0, col, row)


def simulated_burnin_box(take: Path, width: int) -> tuple[int, int, int, int] | None:
    """(y0, y1, x0, x1) around the frame id a simulated take burns into every frame (it differs between
    cameras by design, so image comparisons leave it out); None for takes that are not simulated."""
    from rigctl.simulators.burnin import block_px

    if not (take / "truth" / "settings.yaml").exists():
        return None
    b = block_px(width)
    return 0, 3 * b + 6, 0, 34 * b + 8  # two rows of 32 blocks, with room for the rectification's warp
