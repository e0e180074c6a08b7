"""What ``rigctl calibrate`` reads: a take, a folder of frame sets (``<frame>/<camera>.png``), or a flat folder
of images named ``<camera><frame>.<ext>`` (e.g. ``left01.jpg``, ``right01.jpg``), as greyscale images per
camera and frame."""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.errors import CalibrationError
from rigctl.imagefile import png_chunks, png_size
from rigctl.layout import misspelt
from rigctl.regular import read_regular
from rigctl.rig import CAMERA_NAME
from rigctl.take.reader import TakeReader

IMAGE_EXT = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".exr")
_FLAT = re.compile(r"^(?P<camera>[A-Za-z_][A-Za-z_\-]*?)[_\-]?(?P<frame>\d+)$")


@dataclass
class CalibrationViews:
    """Greyscale images by (camera, frame). ``names`` are grid names (``r{row}c{col}``); ``source_names`` the
    names in the input when they differed (``left`` -> ``r0c0``)."""

    source: Path
    names: list[str]
    frames: list[str]
    image_size: tuple[int, int]
    _load: dict[tuple[str, str], object] = field(repr=False, default_factory=dict)
    source_names: dict[str, str] = field(default_factory=dict)
    rig: str = ""
    truth: Path | None = None

    def image(self, camera: str, frame: str) -> NDArray[np.uint8] | None:
        loader = self._load.get((camera, frame))
        if loader is None:
            return None
        img = loader() if callable(loader) else None
        return None if img is None else np.asarray(img, dtype=np.uint8)

    def items(self) -> Iterator[tuple[str, str]]:
        for cam in self.names:
            for frame in self.frames:
                if (cam, frame) in self._load:
                    yield cam, frame


def _grid_names(names: list[str], where: Path) -> dict[str, str]:
    """Input camera names -> grid names: kept when already r{row}c{col}; ``left``/``right`` -> a 1x2 grid. A grid
    position written another way (``r01c0``) is refused naming the name to use, as in a grid folder."""
    for n in names:
        if wrong := misspelt(n):
            raise CalibrationError(f"{where}: camera {n} (its images' name) {wrong}")
    if all(CAMERA_NAME.match(n) for n in names):
        return {n: n for n in names}
    lower = {n.lower(): n for n in names}
    if set(lower) == {"left", "right"}:
        return {lower["left"]: "r0c0", lower["right"]: "r0c1"}
    raise CalibrationError(
        f"{where}: camera names {', '.join(sorted(names))} are not grid positions r{{row}}c{{col}} "
        "(rename the images, or use left/right for a stereo pair)"
    )


MAX_IMAGE_BYTES = 1 << 30  # an image file larger than this is no camera's picture


def _imread_grey(path: Path) -> NDArray[np.uint8]:
    """A picture file as grey: a regular file only (a FIFO would block the read for ever, a device never end),
    its size bounded before it is read, refused in one line when it does not decode."""
    png = path.suffix.lower() == ".png"
    if png:  # its header's size checked before OpenCV decodes (and warns about) it
        png_size(path, CalibrationError)
    data = read_regular(path, MAX_IMAGE_BYTES, CalibrationError, "image")
    if png:  # its chunks proven whole: a damaged one is our line, not libpng's on stderr
        data = png_chunks(path, data, CalibrationError)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise CalibrationError(f"{path}: cannot read the image")
    return np.asarray(img)


def _read_grey(path: Path) -> object:
    return lambda: _imread_grey(path)


def _from_take(folder: Path) -> CalibrationViews:
    reader = TakeReader(folder)
    sets = reader.complete_sets() or reader.frame_sets
    frames = [str(s.number) for s in sets]
    loads: dict[tuple[str, str], object] = {}
    for s in sets:
        for cam, i in s.members.items():

            def load(cam: str = cam, i: int = i) -> NDArray[np.uint8]:
                rgb = reader.frame_rgb(cam, i)
                return np.asarray(np.clip(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) * 255 + 0.5, 0, 255), np.uint8)

            loads[(cam, str(s.number))] = load
    names = _grid_names(reader.names, folder)
    truth = folder / "truth" / "calibration.yaml"
    return CalibrationViews(
        folder,
        [names[n] for n in reader.names],
        frames,
        (reader.width, reader.height),
        {(names[c], f): v for (c, f), v in loads.items()},
        rig=str(reader.manifest.rig.get("name", "")),
        truth=truth if truth.exists() else None,
    )


def load_views(path: Path) -> CalibrationViews:
    """The images of a take or an image folder; errors name the path and what is wrong."""
    path = Path(path)
    if not path.exists():
        raise CalibrationError(f"{path}: no such take or folder")
    if (path / "take.yaml").exists():
        return _from_take(path)
    if not path.is_dir():
        raise CalibrationError(f"{path}: not a take or a folder of images")
    found: dict[tuple[str, str], Path] = {}
    subdirs = sorted(p for p in path.iterdir() if p.is_dir())
    for sub in subdirs:  # <frame>/<camera>.png
        for img in sorted(sub.iterdir()):
            if img.suffix.lower() in IMAGE_EXT:
                found[(img.stem, sub.name)] = img
    if not found:  # <camera><frame>.<ext>
        for img in sorted(path.iterdir()):
            m = _FLAT.match(img.stem)
            if img.suffix.lower() in IMAGE_EXT and m:
                found[(m["camera"], m["frame"])] = img
    if not found:
        raise CalibrationError(
            f"{path}: no images found (expected a take, <frame>/<camera>.png, or <camera><frame>.png files)"
        )
    raw_names = sorted({c for c, _ in found})
    names = _grid_names(raw_names, path)
    frames = sorted({f for _, f in found}, key=lambda f: (len(f), f))
    first = _imread_grey(next(iter(found.values())))
    size = (int(first.shape[1]), int(first.shape[0]))
    ordered = sorted(raw_names, key=lambda n: names[n])
    return CalibrationViews(
        path,
        [names[n] for n in ordered],
        frames,
        size,
        {(names[c], f): _read_grey(p) for (c, f), p in found.items()},
        source_names={names[n]: n for n in raw_names if names[n] != n},
    )
