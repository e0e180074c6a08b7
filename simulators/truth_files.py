"""The ground truth of a simulated take on disk: ``truth/`` beside its frames."""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml
from numpy.typing import NDArray
from rigctl.simulators.soft_edges import soft_truth

from rigctl.pfm import write_pfm
from rigctl.publish import publish_png

if TYPE_CHECKING:
    from rigctl.simulators.array import SimArray

log = logging.getLogger(__name__)


def write_truth(array: SimArray, folder: Path, frame_sets: list[tuple[int, dict[str, int]]]) -> None:
    """Write ``truth/``: the true calibration, per frame set and camera the disparity (PFM), the
    subject matte (PNG; the pixel centre's ray), with ``edges=soft`` the alpha (PFM, the share of the pixel
    the subject covers) and the unmixed foreground colour (RGB PFM, 0 where alpha is 0) and, for the charuco
    scene, the board's pose. ``frame_sets`` lists
    (frame set number, {camera: scene frame on the common grid}). Repeated scene states are hard
    links, not copies."""
    folder.mkdir(parents=True, exist_ok=True)
    array.calibration.save(folder / "calibration.yaml")
    (folder / "settings.yaml").write_text(yaml.safe_dump(array.requested.model_dump(mode="json"), sort_keys=False))
    first_file: dict[tuple[int, str, str], Path] = {}
    poses: dict[int, dict[str, object]] = {}
    kinds = [("disparity", ".pfm"), ("matte", ".png")]
    if array.settings.edges == "soft":
        kinds += [("alpha", ".pfm"), ("foreground", ".pfm")]
    soft: dict[int, tuple[list[NDArray[np.float32]], list[NDArray[np.float32]]]] = {}
    for number, members in frame_sets:
        out = folder / "disparity" / f"{number:06d}"
        out.mkdir(parents=True, exist_ok=True)
        scene_frames = set(members.values())
        if len(scene_frames) != 1:
            log.warning("frame set %d mixes scene frames %s; truth follows the first", number, scene_frames)
        state = array.state_of(min(scene_frames))
        if array.settings.scene == "charuco":
            pose = array.board_poses[state]
            poses[number] = {"R": pose.R.tolist(), "origin": pose.origin.tolist(), "state": state}
        for name in members:
            for kind, suffix in kinds:
                target = folder / kind / f"{number:06d}" / f"{name}{suffix}"
                target.parent.mkdir(parents=True, exist_ok=True)
                key = (state, name, kind)
                if key in first_file:
                    os.link(first_file[key], target)
                    continue
                disp, mattes = array.truth(state)
                i = array.index[name]
                if kind in ("alpha", "foreground"):
                    if state not in soft:
                        soft[state] = soft_truth(array, state)
                    write_pfm(target, soft[state][kind == "foreground"][i], durable=False)
                elif kind == "disparity":
                    write_pfm(target, disp[i], durable=False)  # truth is made again from settings
                else:
                    publish_png(target, mattes[i].astype(np.uint8) * 255, durable=False)
                first_file[key] = target
    if poses:
        doc = {"board": array.board.as_dict(), "poses": poses}
        (folder / "board_poses.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
