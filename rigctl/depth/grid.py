"""Rectified camera grids as depth input: a take whose manifest has a rectification section (``rigctl
rectify``'s output, or an ``ideal=true`` simulated take, rectified as recorded), or a grid folder
(``r{row}c{col}.png`` + ``grid.yaml``).

A grid holds each picture as it came: a take's frame bytes in their captured format, 8-bit BGR from an 8-bit
PNG, float RGB from a 16-bit PNG or an array. What an engine reads is derived from it, each straight from what
was given, so a take's frames reach the matcher without a float round trip and the float picture is not quantised on
the way: :meth:`Grid.bgr8` (8-bit BGR: the semi-global matcher) and :meth:`FrameImages.grey` (the cost volume's
grey) are made on first use and kept (the greys while they fit in ``GREY_KEEP_BYTES``); ``grid.images[name]`` (float
RGB in [0, 1]: the keyer, the EXR picture) is made when asked and only the last one kept, and
:meth:`FrameImages.region` makes a part of it (issue 24: nine float pictures held for the whole frame set were 0.83
GiB at 3840x2160)."""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.errors import ParameterError, RigFileError, TakeError
from rigctl.pixfmt import bgr8_to_rgb, to_bgr8, to_rgb, to_u8
from rigctl.rig import CAMERA_NAME
from rigctl.take.reader import TakeReader
from rigctl.timecode import Timecode

log = logging.getLogger(__name__)

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
# greys kept for a frame set's estimates up to this many bytes (nine of 1920x1080 are 75 MB); beyond it each
# read makes its grey again, GREY_BAND_ROWS rows at a time (issue 24: nine of 3840x2160 are 0.28 GiB held
# through the estimates' peak, where making them again costs a few % of the time)
GREY_KEEP_BYTES = 96 << 20
GREY_BAND_ROWS = 64


def grey(rgb: F32) -> F32:
    """The grey the cost volume matches (OpenCV's RGB to grey of float RGB)."""
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(rgb, np.float32), cv2.COLOR_RGB2GRAY), dtype=np.float32)


class FrameImages(Mapping[str, F32]):
    """The pictures of a grid by camera: float RGB in [0, 1] when read as a mapping, 8-bit BGR through
    :meth:`bgr8`, the grey through :meth:`grey`; each from the picture as given (8-bit BGR or float RGB) or
    straight from a take's captured bytes (:meth:`captured`), so neither goes through the other. The 8-bit
    pictures and the greys are kept once made; a float picture that was not given is made when asked, and
    only the last one made is kept (the reads of one camera follow each other)."""

    def __init__(self, images: Mapping[str, NDArray[Any]]) -> None:
        self._names = list(images)
        self._u8: dict[str, U8] = {n: v for n, v in images.items() if v.dtype == np.uint8}
        self._u8_made: set[str] = set()  # 8-bit pictures made here (the others were given)
        self._float: dict[str, F32] = {n: v for n, v in images.items() if v.dtype != np.uint8}
        self._captured: dict[str, U8] = {}
        self._format = ("", 0, 0)
        self._grey: dict[str, F32] = {}
        self._last: tuple[str, F32] | None = None  # the last float picture made (one assignment: thread-safe)

    @classmethod
    def captured(cls, frames: Mapping[str, U8], pixel_format: str, width: int, height: int) -> FrameImages:
        """Pictures still in a take's captured pixel format (frame bytes as read)."""
        out = cls({})
        out._names = list(frames)
        out._captured = dict(frames)
        out._format = (pixel_format, width, height)
        return out

    def __getitem__(self, name: str) -> F32:
        rgb = self._float.get(name)
        if rgb is not None:
            return rgb
        last = self._last
        if last is not None and last[0] == name:
            return last[1]
        rgb = self._made(name)
        self._last = (name, rgb)
        return rgb

    def _made(self, name: str) -> F32:
        """The float picture of a camera whose picture was not given as float, made anew."""
        if name in self._captured:
            return to_rgb(self._captured[name], *self._format)
        return bgr8_to_rgb(self._u8[name])  # KeyError for a camera the grid does not have, as a mapping's

    def fresh(self, name: str) -> F32:
        """Camera ``name``'s float picture as a new array, neither kept here nor shared (a copy of a given
        one): the caller's to change, and gone when the caller lets go of it (issue 24: the write's soft key,
        which makes its picture twice rather than hold one through its solve)."""
        rgb = self._float.get(name)
        return rgb.copy() if rgb is not None else self._made(name)

    def forget_last(self) -> None:
        """Let go of the last float picture made (made again if asked: the same values): the depth's search
        reads only the greys (issue 24: 0.1 GiB at 4K through each camera's search)."""
        self._last = None

    def __contains__(self, name: object) -> bool:
        return name in self._names  # without making the picture (a Mapping's own test reads it)

    def region(self, name: str, rows: slice, cols: slice) -> F32:
        """``self[name][rows, cols]``, made from that part alone when the picture came as 8-bit BGR (the same
        values: the conversion is per pixel)."""
        last = self._last
        if name in self._u8 and name not in self._float and (last is None or last[0] != name):
            return bgr8_to_rgb(self._u8[name][rows, cols])
        return self[name][rows, cols]

    def grey(self, name: str) -> F32:
        """:func:`grey` of the float picture (every camera's estimate reads every view's), kept while the greys
        kept stay within ``GREY_KEEP_BYTES``, else made again on each read (:meth:`grey_rows`); the float
        picture made for it is not kept."""
        g = self._grey.get(name)
        if g is not None:
            return g
        g = self.grey_rows(name, 0, self.shape()[0])
        if g.nbytes + sum(k.nbytes for k in self._grey.values()) <= GREY_KEEP_BYTES:
            self._grey[name] = g
        return g

    def grey_rows(self, name: str, a: int, b: int) -> F32:
        """Rows a..b of :meth:`grey`, made from those rows alone when the grey is not kept: from the 8-bit or
        captured picture ``GREY_BAND_ROWS`` rows at a time (the same values: the conversions are per pixel
        and a row of every format is its own bytes; ``tests/unit/test_take_model.py``)."""
        kept = self._grey.get(name)
        if kept is not None or b <= a:
            return kept[a:b] if kept is not None else np.empty((0, self.shape()[1]), np.float32)
        last, given = self._last, self._float.get(name)
        rgb = given if given is not None else last[1] if last is not None and last[0] == name else None
        if rgb is not None:
            return grey(rgb[a:b])
        out = np.empty((b - a, self.shape()[1]), np.float32)
        for r in range(a, b, GREY_BAND_ROWS):
            out[r - a : min(b, r + GREY_BAND_ROWS) - a] = grey(self._rows(name, r, min(b, r + GREY_BAND_ROWS)))
        return out

    def _rows(self, name: str, a: int, b: int) -> F32:
        """Rows a..b of the float picture of a camera whose picture was not given as float."""
        if name in self._captured:
            pixel_format, width, height = self._format
            return to_rgb(self._captured[name].reshape(height, -1)[a:b], pixel_format, width, b - a)
        return bgr8_to_rgb(self._u8[name][a:b])

    def bgr8(self, name: str) -> U8:
        bgr = self._u8.get(name)
        if bgr is None:
            if name in self._captured:
                bgr = to_bgr8(self._captured[name], *self._format)
            else:
                bgr = np.ascontiguousarray(to_u8(self._float[name]))
            self._u8[name] = bgr
            self._u8_made.add(name)
        return bgr

    def made_bytes(self) -> int:
        """The bytes held of what was made from the pictures (greys, 8-bit copies, the last float picture)."""
        last = self._last[1].nbytes if self._last is not None else 0
        return last + sum(g.nbytes for g in self._grey.values()) + sum(self._u8[n].nbytes for n in self._u8_made)

    def drop_made(self) -> None:
        """Let go of what was made from the pictures (made again if asked: the same values). The depth keeps
        every camera's grey and 8-bit picture through a frame set's estimates; its write needs neither (issue
        24: the nine greys alone are 0.28 GiB at 3840x2160)."""
        self._grey = {}
        self._last = None
        for name in self._u8_made:
            del self._u8[name]
        self._u8_made = set()

    def shape(self) -> tuple[int, int]:
        if self._captured:
            return self._format[2], self._format[1]
        first = self._names[0]
        img = self._u8[first] if first in self._u8 else self._float[first]
        return int(img.shape[0]), int(img.shape[1])

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


def grey_of(images: Mapping[str, F32], name: str, rows: tuple[int, int] | None = None) -> F32:
    """Camera ``name``'s grey (``rows``: a..b of it alone): the grid's pictures' (:meth:`FrameImages.grey`),
    else made."""
    if rows is None:
        return images.grey(name) if isinstance(images, FrameImages) else grey(images[name])
    a, b = rows
    return images.grey_rows(name, a, b) if isinstance(images, FrameImages) else grey(images[name][a:b])


@dataclass
class Grid:
    """One frame of a rectified grid. ``offsets`` are each camera's position relative to the grid origin in
    units of the horizontal spacing (x right, y down): a point with disparity d at (x, y) in camera a lies at
    (x - d (ox_b - ox_a), y - d (oy_b - oy_a)) in camera b."""

    names: list[str]
    images: Mapping[str, NDArray[Any]]  # as given: 8-bit BGR or float RGB; read back as float RGB in [0, 1]
    offsets: dict[str, tuple[float, float]]
    focal_px: float
    spacing: float  # horizontal spacing, in the unit depth is reported in (metres for takes)
    doffs: float = 0.0
    disparity_range: tuple[float, float] | None = None
    truth: dict[str, F32] | None = None
    meta: dict[str, str | int] = field(default_factory=dict)
    # the rectified frame, when the source has one (a take's rectification): each camera's centre in it and
    # the principal point of the common K; a grid folder has neither (see :meth:`centre`)
    positions: Mapping[str, tuple[float, float, float]] | None = None
    principal: tuple[float, float] | None = None
    frames: FrameImages = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.frames = self.images if isinstance(self.images, FrameImages) else FrameImages(self.images)
        self.images = self.frames

    def bgr8(self, name: str) -> U8:
        """Camera ``name``'s picture as 8-bit BGR (the picture itself when it came as 8 bits)."""
        return self.frames.bgr8(name)

    @property
    def shape(self) -> tuple[int, int]:
        return self.frames.shape()

    def centre(self, name: str) -> tuple[float, float, float]:
        """Camera ``name``'s centre in the rectified frame (x right, y down, z ahead); without one (a grid
        folder), derived from its offset: (ox, oy, 0) times the spacing, r0c0 at the origin."""
        if self.positions is not None and name in self.positions:
            return self.positions[name]
        ox, oy = self.offsets[name]
        return ox * self.spacing, oy * self.spacing, 0.0

    def depth(self, disparity: F32) -> F32:
        """Z = f * spacing / (d + doffs); +inf where there is no estimate or d + doffs <= 0."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a tiny d + doffs: Z overflows, +inf
            den = disparity + np.float32(self.doffs)
            z = np.where(np.isfinite(den) & (den > 0), self.focal_px * self.spacing / den, np.inf)
        return np.asarray(z, dtype=np.float32)


def _check_image(img: NDArray[Any], where: str) -> NDArray[Any]:
    """Float RGB (or grey, made RGB), finite; 8-bit pictures (BGR) are kept as they are."""
    if img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3:
        return img
    arr = np.asarray(img, dtype=np.float32)
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=2)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ParameterError(f"{where}: expected an RGB or grey image, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{where}: image holds NaN or infinite values: refused")
    return arr


def grid_from_arrays(
    images: dict[str, NDArray[Any]],
    focal_px: float,
    spacing_x: float,
    spacing_y: float,
    doffs: float = 0.0,
    disparity_range: tuple[float, float] | None = None,
) -> Grid:
    """A grid from images named r{row}c{col} on a regular lattice (spacings in one unit): float RGB (or grey)
    in [0, 1], or 8-bit BGR."""
    if not images:
        raise ParameterError("a grid needs at least one camera")
    for n in images:
        if not CAMERA_NAME.match(n):
            raise ParameterError(f"camera {n!r} is not a grid position r{{row}}c{{col}}")
    if not (math.isfinite(focal_px) and focal_px > 0 and math.isfinite(spacing_x) and spacing_x > 0):
        raise ParameterError(f"focal_px and spacing_x must be positive and finite, got {focal_px}, {spacing_x}")
    if not (math.isfinite(spacing_y) and spacing_y >= 0):
        raise ParameterError(f"spacing_y must be finite and >= 0, got {spacing_y}")
    imgs = {n: _check_image(v, f"camera {n}") for n, v in images.items()}
    shapes = {v.shape for v in imgs.values()}
    if len(shapes) != 1:
        raise ParameterError(f"grid images differ in size: {sorted(shapes)}")
    offsets = {}
    for n in imgs:
        m = CAMERA_NAME.match(n)
        assert m is not None
        r, c = int(m[1]), int(m[2])
        offsets[n] = (float(c), r * spacing_y / spacing_x)
    names = sorted(imgs, key=lambda n: (offsets[n][1], offsets[n][0]))
    return Grid(names, imgs, offsets, float(focal_px), float(spacing_x), float(doffs), disparity_range)


def read_truth(path: Path, shape: tuple[int, int]) -> F32:
    """A reference disparity PFM (+inf where undefined), refused unless it is the pictures' size and free of
    NaN: scored as it was, a smaller one ended depth in a traceback and one of NaN read as 0 % bad."""
    from rigctl.pfm import read_pfm

    d = read_pfm(path)
    if d.shape != shape:
        raise RigFileError(f"{path}: reference disparity is {d.shape[::-1]} px, the images {shape[::-1]}")
    if np.isnan(d).any():
        raise RigFileError(f"{path}: reference disparity holds NaN (undefined is +inf): refused")
    return d


def read_truths(folder: Path, names: list[str], shape: tuple[int, int]) -> dict[str, F32]:
    """The reference disparity ``folder/<camera>.pfm`` of each camera that has one. One is there when its name
    is (``os.path.lexists``): a FIFO, a device, a folder, a symlink loop or a dangling symlink in its place is
    refused in one line by :func:`read_truth` (opened without blocking), not skipped as if it were absent."""
    return {n: read_truth(folder / f"{n}.pfm", shape) for n in names if os.path.lexists(folder / f"{n}.pfm")}


def camera_offsets(
    positions_m: Mapping[str, Any], names: list[str], spacing: float, where: str
) -> dict[str, tuple[float, float]]:
    """Each camera's position relative to the cameras' mean, in units of the horizontal ``spacing`` (x right,
    y down): the grid's ``offsets``. Every camera of ``names`` needs a position: one without is refused,
    naming ``where`` (the take or calibration it came from) and the camera."""
    missing = [n for n in names if n not in positions_m]
    if missing:
        raise TakeError(f"{where}: no rectified position for camera(s) {', '.join(missing)}")
    positions = {n: np.asarray(positions_m[n], float) for n in names}
    origin = np.mean([positions[n] for n in names], axis=0)
    rel = {n: positions[n] - origin for n in names}
    return {n: (float(rel[n][0] / spacing), float(rel[n][1] / spacing)) for n in names}


def rectified_frame(
    positions_m: Mapping[str, Any], K: Any
) -> tuple[dict[str, tuple[float, float, float]], tuple[float, float]]:
    """A rectification's cameras' centres and its common principal point: a :class:`Grid`'s ``positions``
    and ``principal``."""
    positions = {n: (float(p[0]), float(p[1]), float(p[2])) for n, p in positions_m.items()}
    return positions, (float(K[0][2]), float(K[1][2]))


def grid_order(offsets: Mapping[str, tuple[float, float]]) -> list[str]:
    """Camera names row by row, left to right."""
    return sorted(offsets, key=lambda n: (offsets[n][1], offsets[n][0]))


class SkippedFrameSet(Exception):
    """A frame set left out because one of its frames is damaged (``skip_damaged``)."""


class TakeFrames:
    """What every frame source reading a take shares: its complete frame sets, their rate and timecode."""

    flat = False  # one folder per frame set
    doffs = 0.0
    disparity_range: tuple[float, float] | None = None  # a take carries no plan of its own
    reader: TakeReader
    folder: Path

    @property
    def name(self) -> str:
        return str(self.folder)

    def frame_numbers(self) -> list[int]:
        return [s.number for s in self.reader.complete_sets()]

    def timing(self, number: int) -> tuple[float | None, Timecode | None]:
        """The rate and the frame set's timecode, which the pictures carry."""
        sets = {s.number: s for s in self.reader.frame_sets}
        return self.reader.fps, self.reader.set_timecode(sets[number])

    def members(self, number: int) -> dict[str, int]:
        """Frame set ``number``'s frame of each camera; refused when it is not a complete frame set."""
        sets = {s.number: s for s in self.reader.complete_sets()}
        if number not in sets:
            raise ParameterError(f"{self.folder}: frame set {number} is not complete or does not exist")
        return dict(sets[number].members)


class TakeGrid(TakeFrames):
    """Frame sets of a take whose manifest has a rectification section, as grids of 8-bit BGR pictures (a
    ``rigctl.depth.sources.FrameSource``)."""

    def __init__(self, folder: Path, skip_damaged: bool = False) -> None:
        self.reader = TakeReader(folder, skip_damaged=skip_damaged)
        rect = self.reader.manifest.rectification
        if rect is None:
            raise TakeError(
                f"{folder}: not a rectified take (run rigctl rectify first; ideal=true simulated takes are "
                "rectified as recorded, and one recorded before they said so is rectified with its "
                "truth/calibration.yaml)"
            )
        self.focal_px = rect.focal_px
        self.spacing = rect.spacing_x_m
        self.offsets = camera_offsets(rect.positions_m, self.reader.names, self.spacing, str(folder))
        self.positions, self.principal = rectified_frame(rect.positions_m, rect.K)
        self.names = grid_order(self.offsets)
        self.folder = folder

    def grid(self, number: int) -> Grid:
        members = self.members(number)
        frames: dict[str, U8] = {}
        for n in self.names:
            data = self.reader.frame_or_none(n, members[n])
            if data is None:
                raise SkippedFrameSet(number)  # a damaged frame, skipped: listed in reader.damaged
            frames[n] = data
        r = self.reader
        images = FrameImages.captured(frames, r.pixel_format, r.width, r.height)
        truth = None
        tdir = self.folder / "truth" / "disparity" / f"{number:06d}"
        if tdir.is_dir():
            truth = read_truths(tdir, self.names, images.shape())
        return Grid(
            list(self.names),
            images,
            dict(self.offsets),
            self.focal_px,
            self.spacing,
            truth=truth,
            meta={"take": str(self.folder), "frame": number},
            positions=self.positions,
            principal=self.principal,
        )
