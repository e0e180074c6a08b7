"""Render input: the colour of a rectified grid (a rectified take, an ideal simulated take or a grid folder)
and the disparity of its cameras read from a folder of PFM files (``<frame>/<camera>.pfm``: a depth output
or a take's ``truth/disparity``), or a depth output's EXRs where it has no PFM (``rigctl.disparity_layers``).
Nothing here depends on how the disparities were made."""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np
from numpy.typing import NDArray

from rigctl.depth.sources import FrameSource, open_source
from rigctl.disparity_layers import checked_disparity, disparity_file, read_any_disparity
from rigctl.errors import ParameterError, TakeError
from rigctl.keying import Keyer
from rigctl.regular import read_regular
from rigctl.rig import CAMERA_NAME
from rigctl.take.framesets import check_frames, ranges
from rigctl.timecode import Timecode

log = logging.getLogger(__name__)

F32 = NDArray[np.float32]


@dataclass
class View:
    """One camera of a frame: RGB in [0, 1], its key (subject opacity) and its disparity (None: not given)."""

    name: str
    offset: tuple[float, float]  # position in the array plane, in horizontal spacings (x right, y down)
    rgb: F32
    alpha: F32
    disparity: F32 | None
    keyed: bool  # False when the image shows no screen (alpha is all ones)


@dataclass
class FrameViews:
    """One frame set as the renderer reads it: each camera's view (colour, alpha, disparity) and the grid's scale."""

    number: int
    views: dict[str, View]
    focal_px: float
    spacing: float  # horizontal spacing (metres for takes; the grid folder's unit otherwise)
    estimated: set[str] | None = None  # the cameras whose disparity has an estimate somewhere (None: not known)

    @property
    def shape(self) -> tuple[int, int]:
        h, w = next(iter(self.views.values())).rgb.shape[:2]
        return h, w

    def position(self, col: float, row: float) -> tuple[float, float]:
        """Grid units (column, row; ``1,1`` is r1c1) -> offset in the array plane, fitted to the cameras'
        own offsets (a rectified take's cameras are not exactly on the lattice)."""
        return grid_position(self.views, col, row)


def grid_position(views: dict[str, View], col: float, row: float) -> tuple[float, float]:
    if not (math.isfinite(col) and math.isfinite(row)):
        raise ParameterError(f"position {col},{row}: must be finite grid units")
    names = list(views)
    rc = np.array([_row_col(n) for n in names], float)
    off = np.array([views[n].offset for n in names], float)
    design = np.column_stack([np.ones(len(names)), rc[:, 1], rc[:, 0]])
    coef, *_ = np.linalg.lstsq(design, off, rcond=None)
    cols, rows = rc[:, 1], rc[:, 0]
    if not (cols.min() - 1 <= col <= cols.max() + 1 and rows.min() - 1 <= row <= rows.max() + 1):
        raise ParameterError(
            f"position {col:g},{row:g}: outside the array (columns {cols.min():g}..{cols.max():g}, rows "
            f"{rows.min():g}..{rows.max():g}); more than one camera spacing beyond it, no camera sees the view"
        )
    x, y = np.array([1.0, col, row]) @ coef
    if len({r for r, _c in rc.tolist()}) == 1 and row != rc[0, 0]:
        raise ParameterError(f"position {col},{row}: the grid has one row ({int(rc[0, 0])}); row must be that")
    if len({c for _r, c in rc.tolist()}) == 1 and col != rc[0, 1]:
        raise ParameterError(f"position {col},{row}: the grid has one column ({int(rc[0, 1])}); col must be that")
    return float(x), float(y)


def _row_col(name: str) -> tuple[int, int]:
    m = CAMERA_NAME.match(name)
    if m is None:
        raise ParameterError(f"camera {name!r} is not a grid position r{{row}}c{{col}}")
    return int(m[1]), int(m[2])


class RenderInput:
    """A grid's frames together with their disparities from ``disparity_dir``."""

    def __init__(
        self, source: Path, disparity_dir: Path, keyer: Keyer | None = None, refuse_unestimated: bool = True
    ) -> None:
        """``refuse_unestimated``: a frame set none of whose disparities holds an estimate is refused in one
        line when read (a render or score of it is empty); the web viewer shows it as it is, empty."""
        self.source = source
        self.refuse_unestimated = refuse_unestimated
        self.disparity_dir = disparity_dir
        self.keyer = keyer or Keyer()
        if not disparity_dir.is_dir():
            what = "is not a folder" if disparity_dir.exists() else "does not exist"
            raise ParameterError(f"{disparity_dir}: disparity folder {what}")
        self._last: FrameViews | None = None
        self.frames: FrameSource = open_source(source)
        self.numbers = self.frames.frame_numbers()
        if not self.numbers:
            raise ParameterError(f"{source}: the take has no complete frame set")
        made_from = _made_from(disparity_dir)
        if made_from is not None and not _same_folder(made_from, source):
            log.warning(
                "%s was made from %s, not from %s: unless those are the same pictures, the views will be wrong",
                disparity_dir, made_from, source,
            )  # fmt: skip

    def select(self, frames: range | None) -> list[int]:
        """The frames to render: those asked for (each a complete frame set with a disparity), or by default
        every complete frame set the disparity folder has. Checked before anything is written."""
        if frames is None:
            chosen = [n for n in self.numbers if self._has_disparity(n)]
            if not chosen:
                self._no_disparity(self.numbers[0])
            if len(chosen) < len(self.numbers):
                log.warning(
                    "%s has disparities for %d of the %d complete frame sets of %s: rendering those (%s)",
                    self.disparity_dir, len(chosen), len(self.numbers), self.source, ranges(chosen),
                )  # fmt: skip
            return chosen
        chosen = check_frames(frames, self.numbers, self.source)
        for f in chosen:
            if not self._has_disparity(f):
                self._no_disparity(f)
        return chosen

    def _names(self) -> list[str]:
        return list(self.frames.names)

    def _has_disparity(self, number: int) -> bool:
        return any(self._disparity_file(number, n).exists() for n in self._names())

    def _no_disparity(self, number: int) -> NoReturn:
        names = self._names()
        folder = self._disparity_file(number, names[0]).parent
        raise TakeError(
            f"{self.disparity_dir}: no disparity for frame {number} of {self.source} "
            f"(expected {folder}/<camera>.exr or .pfm for cameras {', '.join(names)})"
        )

    def _disparity_file(self, number: int, name: str) -> Path:
        folder = self.disparity_dir / f"{number:06d}"
        if self.frames.flat and not folder.is_dir():
            folder = self.disparity_dir  # a grid folder's depth output has no frame level
        return disparity_file(folder, name)

    def timing(self, number: int) -> tuple[float | None, Timecode | None]:
        """A take's rate and frame set ``number``'s timecode, which its views carry (None for a grid folder)."""
        return self.frames.timing(number)

    def view_camera(self, frame: FrameViews, offset: tuple[float, float]) -> dict[str, object]:
        """``worldToCamera`` and ``worldToNDC`` (OpenEXR's attributes, ``rigctl.exrcam``) of a view
        at ``offset`` (in spacings from the cameras' mean, as :meth:`FrameViews.position` gives it), in the
        take's rectified frame (a grid folder's: r0c0 at the origin, principal point at the centre)."""
        from rigctl.exrcam import camera_attributes

        h, w = frame.shape
        origin = np.zeros(3)
        principal = None  # a grid folder's: the picture's centre
        reader = getattr(self.frames, "reader", None)  # a take's (rectified, or rectified as it is read)
        rect = reader.manifest.rectification if reader is not None else None
        if rect is not None:
            origin = np.mean([rect.positions_m[n] for n in frame.views], axis=0)
            principal = (float(rect.K[0][2]), float(rect.K[1][2]))
        centre = origin + np.array([offset[0] * frame.spacing, offset[1] * frame.spacing, 0.0])
        return camera_attributes(centre, frame.focal_px, principal, (w, h))

    def frame(self, number: int) -> FrameViews:
        """Frame ``number``'s colour, key and disparity (the last one asked for is kept: the CLI reads the
        first frame's size before rendering it, and should neither read it nor warn about it twice)."""
        if self._last is not None and self._last.number == number:
            return self._last
        self._last = self._read(number)
        return self._last

    def _read(self, number: int) -> FrameViews:
        grid = self.frames.grid(number)
        h, w = grid.shape
        files = {n: self._disparity_file(number, n) for n in grid.names}
        found = {n: p for n, p in files.items() if p.exists()}
        if not found:
            self._no_disparity(number)
        disps: dict[str, F32] = {}
        for n, path in found.items():
            disps[n] = checked_disparity(path, read_any_disparity(path), (h, w), self.source)
        estimated = {n for n, d in disps.items() if bool(np.isfinite(d).any())}
        if not estimated and self.refuse_unestimated:  # every view would be empty, every score one of nothing
            raise TakeError(
                f"{self.disparity_dir}: frame {number}: no camera's disparity holds an estimate (every value is "
                "+inf, no estimate): nothing to render from"
            )
        views = {}
        for n in grid.names:
            rgb = grid.images[n]
            screen = self.keyer.screen_excess(rgb) > 0
            alpha = self.keyer.matte(rgb) if screen else np.ones((h, w), np.float32)
            views[n] = View(n, grid.offsets[n], rgb, alpha, disps.get(n), screen)
        missing = sorted(set(files) - set(found))
        if missing:
            log.warning("frame %d: no disparity for %s: not used as sources", number, ", ".join(missing))
        return FrameViews(number, views, grid.focal_px, grid.spacing, estimated)


def _made_from(disparity_dir: Path) -> Path | None:
    """The folder a disparity folder was made from: a take's own ``truth/disparity``, or the ``source`` in a
    depth output's ``report.json`` (None when it does not say, or says it unreadably)."""
    d = disparity_dir.resolve()
    if d.name == "disparity" and d.parent.name == "truth" and (d.parent.parent / "take.yaml").exists():
        return d.parent.parent
    report = disparity_dir / "report.json"
    try:
        source = json.loads(read_regular(report, 1 << 24, TakeError, "report")).get("source")
    except (TakeError, ValueError, AttributeError, RecursionError):
        return None
    return Path(source) if isinstance(source, str) and source else None


def _same_folder(a: Path, b: Path) -> bool:
    """Whether two paths name one folder; a relative path written by another run is compared by its name."""
    if a.is_absolute():
        return a.resolve() == b.resolve()
    return a.resolve() == b.resolve() or a.name == b.resolve().name
