"""Where a take's frame sets come from, as rectified grids: the one interface the take-level pipeline
(``rigctl depth``, ``rigctl process``, the demo, the benchmarks) and rendering read.

* :class:`~rigctl.depth.grid.TakeGrid`: a rectified take (``rigctl rectify``'s output, or an ``ideal=true``
  simulated take);
* :class:`RectifyingGrid`: a take not rectified yet, rectified in memory with a calibration;
* :class:`GridFolder`: a grid folder (one picture, ``grid.yaml``);
* ``rigctl.depth.array_take.ArrayTake``: a simulated take held in memory (benchmarks).
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from rigctl.depth.grid import (
    Grid,
    TakeFrames,
    TakeGrid,
    camera_offsets,
    grid_order,
    rectified_frame,
)
from rigctl.depth.grid_folder import load_grid_folder
from rigctl.errors import ParameterError
from rigctl.timecode import Timecode


class FrameSource(Protocol):
    """Frame sets as grids, with what the pipeline needs besides the pictures."""

    @property
    def name(self) -> str: ...  # what report.json calls the source

    names: list[str]
    focal_px: float
    spacing: float
    doffs: float
    disparity_range: tuple[float, float] | None  # a range the source itself plans (grid.yaml)
    flat: bool  # one picture: outputs go to DIR/<camera>.<ext> in the frames layout

    def frame_numbers(self) -> list[int]: ...

    def grid(self, number: int) -> Grid: ...

    def timing(self, number: int) -> tuple[float | None, Timecode | None]: ...


class RectifyingGrid(TakeFrames):
    """Frame sets of a take that is not rectified yet, rectified in memory with a calibration (the grid is the
    one ``rigctl rectify`` then ``rigctl depth`` would see: the same tables and the same 8-bit BGR step)."""

    def __init__(self, take: Path, calibration: Path) -> None:
        from rigctl.rectification.rectify import rectifier_for_take
        from rigctl.take.reader import TakeReader

        self.reader = TakeReader(take)
        self.rect = rectifier_for_take(self.reader, calibration)
        rec = self.rect.record()
        self.focal_px = rec.focal_px
        self.spacing = rec.spacing_x_m
        self.offsets = camera_offsets(rec.positions_m, self.reader.names, self.spacing, str(calibration))
        self.positions, self.principal = rectified_frame(rec.positions_m, rec.K)
        self.names = grid_order(self.offsets)
        self.folder = take

    def grid(self, number: int) -> Grid:
        from rigctl.rectification.rectify import frame_bgr

        members = self.members(number)
        images = {n: self.rect.frame(n, frame_bgr(self.reader, n, members[n])) for n in self.names}
        meta: dict[str, str | int] = {"take": str(self.folder), "frame": number}
        return Grid(
            list(self.names), images, dict(self.offsets), self.focal_px, self.spacing, meta=meta,
            positions=self.positions, principal=self.principal,
        )  # fmt: skip


class OneGrid:
    """A single grid in memory as a source of one frame set (number 0)."""

    flat = True

    def __init__(self, grid: Grid, name: str = "grid") -> None:
        self.label = name
        self.grid0 = grid
        self.names = list(grid.names)
        self.focal_px = grid.focal_px
        self.spacing = grid.spacing
        self.doffs = grid.doffs
        self.disparity_range = grid.disparity_range

    @property
    def name(self) -> str:
        return self.label

    def frame_numbers(self) -> list[int]:
        return [0]

    def timing(self, number: int) -> tuple[float | None, Timecode | None]:
        return None, None

    def grid(self, number: int) -> Grid:
        return self.grid0


class GridFolder(OneGrid):
    """A grid folder: one frame set (number 0), its plan from ``grid.yaml``."""

    def __init__(self, folder: Path) -> None:
        super().__init__(load_grid_folder(folder), str(folder))
        self.folder = folder


def open_source(path: Path, calibration: Path | None = None, skip_damaged: bool = False) -> FrameSource:
    """A take (rectified, or rectified on the fly with ``calibration``) or a grid folder as a frame source;
    anything else is refused in one line."""
    if (path / "take.yaml").exists():
        if calibration is not None:
            return RectifyingGrid(path, calibration)
        return TakeGrid(path, skip_damaged=skip_damaged)
    if calibration is not None:
        raise ParameterError(f"{path}: not a take (no take.yaml): --calibration rectifies takes only")
    if (path / "grid.yaml").exists():
        return GridFolder(path)
    raise ParameterError(f"{path}: not a take (take.yaml) or a grid folder (grid.yaml)")


def frame_size(source: FrameSource) -> tuple[int, int]:
    """Width and height of ``source``'s pictures, as depth writes them: from a take's manifest or a grid held in
    memory, else from its first frame set."""
    if isinstance(source, TakeGrid):
        return source.reader.width, source.reader.height
    if isinstance(source, RectifyingGrid):
        return source.rect.grid.image_size
    grid = source.grid0 if isinstance(source, OneGrid) else source.grid(source.frame_numbers()[0])
    h, w = grid.shape
    return w, h
