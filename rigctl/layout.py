"""Where per-frame, per-camera outputs go: the folder layouts of ``take export``, ``depth`` and later outputs.

``frames`` (the default): ``DIR/<frame:06d>/<camera>.<ext>``, one folder per frame set.
``sequence``: ``DIR/<camera>/<camera>.<frame:06d>.<ext>``, one folder per camera holding a numbered image
sequence, as NUKE's Read node (``<camera>.######.exr``) and Unreal's Img Media Source (one folder of
numbered frames) read them.
"""

from __future__ import annotations

import logging
from pathlib import Path

from rigctl.errors import ParameterError

log = logging.getLogger(__name__)

LAYOUTS = ("frames", "sequence")


def output_path(out: Path, layout: str, frame: int, camera: str, ext: str) -> Path:
    """The file of one camera's output at one frame set; ``ext`` with its dot (``.exr``)."""
    if layout == "frames":
        return out / f"{frame:06d}" / f"{camera}{ext}"
    if layout == "sequence":
        return out / camera / f"{camera}.{frame:06d}{ext}"
    raise ParameterError(f"--layout {layout!r}: choose {' or '.join(LAYOUTS)}")
