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


def describe_attached(rig: Rig) -> dict[str, Any]:
    """Attached devices of every kind the rig uses, and each camera's device: found, missing or simulated."""
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
    return {"v4l2": v4l2, "cameras": cams, "missing": missing}


def open_tally(rig: Rig) -> TallyOutput:
    """The rig's tally output, from its ``tally:`` section."""
    tally = rig.model.tally
    if tally is None:
        raise RigFileError(f"{rig.source}: rig {rig.name} has no tally section (add tally: protocol and port)")
    if tally.protocol == "tsl-umd-3.1":
        from rigctl.drivers.tsl31_output import Tsl31Output

        return Tsl31Output(tally.port, tsl_addresses(rig), pad_with_nul=tally.pad_with_nul)
    raise RigFileError(f"{rig.source}: tally protocol {tally.protocol} is not supported by this build yet")
