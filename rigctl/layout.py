"""Where per-frame, per-camera outputs go: the folder layouts of ``take export``, ``depth`` and later outputs.

``frames`` (the default): ``DIR/<frame:06d>/<camera>.<ext>``, one folder per frame set.
``sequence``: ``DIR/<camera>/<camera>.<frame:06d>.<ext>``, one folder per camera holding a numbered image
sequence, as NUKE's Read node (``<camera>.######.exr``) and Unreal's Img Media Source (one folder of
numbered frames) read them.
``flat`` (a grid folder, one picture): ``DIR/<camera>.<ext>``.

:func:`output_path` is the one function that turns names from data into output paths: a camera name is a
grid position ``r{row}c{col}`` (ASCII digits), a frame a number, an extension a short lower-case word, and
anything else is refused, so a name read from a hostile file can never put a file outside ``DIR``.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

from rigctl.errors import OutputError, ParameterError, TakeError

log = logging.getLogger(__name__)

LAYOUTS = ("frames", "sequence")
# A camera's name is its grid position written one way everywhere (rig files, takes, calibrations, grid folders,
# the command line): ASCII digits without leading zeros. Anchored, so ``match`` and ``fullmatch`` agree (no
# trailing newline, no other digits: ``re``'s ``\d`` would take r٢c1).
SAFE_CAMERA = re.compile(r"\Ar(0|[1-9][0-9]{0,3})c(0|[1-9][0-9]{0,3})\Z")
_OTHER_SPELLING = re.compile(r"\Ar(\d{1,8})c(\d{1,8})\Z")  # a grid position in any digits, leading zeros too
SAFE_EXT = re.compile(r"\.[a-z]{2,4}")
MAX_FRAME = 999_999_999


def check_layout(layout: str) -> None:
    """Refuse an unknown ``--layout`` before any work."""
    if layout not in LAYOUTS:
        raise ParameterError(f"--layout {layout!r}: choose {' or '.join(LAYOUTS)}")


def grid_name(name: object) -> str | None:
    """The camera name of the grid position ``name`` is written as, however it is written (``r01c0``, ``r٢c1``
    and ``r1c0`` are all ``r1c0``); None when ``name`` is no grid position."""
    if not isinstance(name, str) or not (m := _OTHER_SPELLING.fullmatch(name)):
        return None
    right = f"r{int(m[1])}c{int(m[2])}"
    return right if SAFE_CAMERA.fullmatch(right) else None  # beyond 4 digits a side: no position rigctl names


def misspelt(name: object) -> str | None:
    """For a grid position written another way (``r01c0``, ``r٢c1``): what is wrong and the name to use
    (``is written with a leading zero: name it r1c0``); None for a camera name and for anything that is no
    grid position at all. One camera named two ways was two cameras at one place (``r01c0`` beside ``r1c0``)."""
    right = grid_name(name)
    if right is None or right == name:
        return None
    how = "a leading zero" if str(name).isascii() else "digits other than 0-9"
    return f"is written with {how}: name it {right}"


def camera_name_problem(name: object) -> str | None:
    """Why ``name`` is no camera name (a phrase following the name), or None when it is one."""
    if isinstance(name, str) and SAFE_CAMERA.fullmatch(name):
        return None
    return misspelt(name) or "is not a camera name r{row}c{col}"


def safe_camera(name: object, where: str = "camera name") -> str:
    """``name`` when it is a grid position ``r{row}c{col}``; otherwise a one-line :class:`TakeError`."""
    if not isinstance(name, str) or not SAFE_CAMERA.fullmatch(name):
        raise TakeError(f"{where}: {name!r} is not a camera name r{{row}}c{{col}}: refused as a file name")
    return name


def inside(out: Path, folder: Path) -> Path:
    """``folder`` (below ``out``), refused in one line when a folder between them is a symbolic link or not a
    folder: a link planted in the output folder (``out/000001 -> /elsewhere``) would have the run write
    outside it. ``out`` itself may be a link: that is the user's choice of output folder."""
    rel = folder.relative_to(out)
    step = out
    for part in rel.parts:
        step = step / part
        if step.is_symlink() or (step.exists() and not step.is_dir()):
            kind = "a symbolic link" if step.is_symlink() else "not a folder"
            raise OutputError(f"{step}: is {kind} inside the output folder {out}: refused (rigctl writes only in it)")
    return folder


def output_path(out: Path, layout: str, frame: int, camera: str, ext: str) -> Path:
    """The file of one camera's output at one frame set; ``ext`` with its dot (``.exr``)."""
    if layout not in (*LAYOUTS, "flat"):
        check_layout(layout)
    safe_camera(camera)
    if not SAFE_EXT.fullmatch(ext):
        raise ParameterError(f"output extension {ext!r} refused")
    if isinstance(frame, bool) or not isinstance(frame, int) or not 0 <= frame <= MAX_FRAME:
        raise TakeError(f"frame number {frame!r} refused as a file name (0 to {MAX_FRAME})")
    if layout == "frames":
        return inside(out, out / f"{frame:06d}") / f"{camera}{ext}"
    if layout == "sequence":
        return inside(out, out / camera) / f"{camera}.{frame:06d}{ext}"
    return out / f"{camera}{ext}"
