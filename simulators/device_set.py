"""Simulated cameras for a rig's ``sim://`` addresses, with the array's ground truth behind them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rigctl.simulators.array import SimArray
from rigctl.simulators.camera import SimCamera
from rigctl.simulators.settings import parse_sim_args

from rigctl.address import Address
from rigctl.interfaces import Camera
from rigctl.rectification.geometry import rectification_record
from rigctl.rig import Rig
from rigctl.take.manifest import Rectification


class SimTruth:
    """Ground truth of a simulated take, written by the recorder through the generic truth hook."""

    def __init__(self, array: SimArray, cameras: dict[str, SimCamera]) -> None:
        self.array = array
        self.cameras = cameras

    def write_truth(self, folder: Path, frame_sets: list[tuple[int, dict[str, int]]]) -> None:
        delivered = {name: cam.delivered for name, cam in self.cameras.items()}
        self.array.write_truth_for(folder, frame_sets, delivered)

    def rectification(self) -> Rectification | None:
        """An ideal array's frames are in its true calibration's common plane already."""
        if not self.array.settings.ideal:
            return None
        return rectification_record(self.array.calibration, calibration="true (simulated, ideal)")


def simulated_cameras(
    rig: Rig, sim_args: list[str], addresses: dict[str, Address]
) -> tuple[dict[str, Camera], SimTruth, dict[str, Any], str]:
    """The ``sim://`` cameras named in ``addresses`` on one simulated array, its truth, settings and summary."""
    settings = parse_sim_args(sim_args, rig=rig)
    array = SimArray(rig, settings)
    array.render_in_background()  # while preflight measures the disk: the cameras stream sooner
    cams: dict[str, SimCamera] = {}
    for name in addresses:  # each sim://<its name> (rigctl.address.camera_address)
        cams[name] = SimCamera(name, array)
    out: dict[str, Camera] = dict(cams)
    return out, SimTruth(array, cams), settings.model_dump(mode="json"), array.describe()
