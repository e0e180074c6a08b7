"""Calibration targets and corner detection with sub-pixel refinement: ChArUco boards (corners identified
by their markers, so partly visible boards count) and plain chessboards (all corners or none)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.board import BoardSpec
from rigctl.calib import CHESSBOARD_CORNERS, CHESSBOARD_SQUARE
from rigctl.calib.inputs import CalibrationViews
from rigctl.errors import CalibrationError, ParameterError
from rigctl.yamlfile import load_yaml

_SUBPIX = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)


@dataclass(frozen=True)
class Chessboard:
    """A plain chessboard: inner corners across and down, square size (metres, or any unit: "1" = one square)."""

    columns: int
    rows: int
    square: float = 1.0
    window: int = 0  # cornerSubPix half-window in pixels; 0: a fifth of the corner spacing

    def corners(self) -> NDArray[np.float64]:
        g = np.zeros((self.columns * self.rows, 3))
        g[:, :2] = np.mgrid[0 : self.columns, 0 : self.rows].T.reshape(-1, 2) * self.square
        return g

    def describe(self) -> str:
        return f"chessboard {self.columns}x{self.rows} inner corners, square {self.square:g}"


Target = BoardSpec | Chessboard


def target_points(target: Target) -> NDArray[np.float64]:
    return target.corners() if isinstance(target, Chessboard) else target.corners_m()


def describe_target(target: Target) -> str:
    if isinstance(target, Chessboard):
        return target.describe()
    return (
        f"ChArUco {target.squares_x}x{target.squares_y} squares of {target.square_m * 1e3:g} mm, "
        f"markers {target.marker_m * 1e3:g} mm, {target.dictionary}"
    )


def load_target(path: Path) -> Target:
    """A board description: ``type: charuco`` (as ``rigctl board`` writes) or ``type: chessboard``
    with ``columns``, ``rows`` (inner corners) and ``square``."""
    data = load_yaml(path)
    if isinstance(data, dict) and data.get("type") == "chessboard":
        fewest, most = CHESSBOARD_CORNERS
        for key in ("columns", "rows"):
            v = data.get(key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int) or not fewest <= v <= most):
                raise CalibrationError(
                    f"{path}: {key}: must be a whole number of inner corners {fewest} to {most}, got {v!r:.60}"
                )
        try:
            board = Chessboard(int(data["columns"]), int(data["rows"]), float(data.get("square", 1.0)))
        except (KeyError, TypeError, ValueError, OverflowError):
            raise CalibrationError(f"{path}: a chessboard needs columns, rows (inner corners) and square") from None
        lo, hi = CHESSBOARD_SQUARE
        if not lo <= board.square <= hi:  # NaN fails too
            raise CalibrationError(
                f"{path}: square: must be {lo:g} to {hi:g} (metres, millimetres or squares), got {board.square:g}"
            )
        return board
    return BoardSpec.load(path)


@dataclass
class Observations:
    """Every detected corner, one row each: camera index, frame index, corner id, pixel position."""

    cam: NDArray[np.int64]
    frame: NDArray[np.int64]
    pt: NDArray[np.int64]
    uv: NDArray[np.float64]
    n_cams: int
    n_frames: int

    def subset(self, keep: NDArray[np.bool_]) -> Observations:
        return Observations(self.cam[keep], self.frame[keep], self.pt[keep], self.uv[keep], self.n_cams, self.n_frames)

    def views(self) -> NDArray[np.int64]:
        """(cameras, frames): corners per view."""
        v = np.zeros((self.n_cams, self.n_frames), np.int64)
        np.add.at(v, (self.cam, self.frame), 1)
        return v


def _charuco(target: BoardSpec) -> Callable[[NDArray[np.uint8]], tuple[NDArray[np.int64], NDArray[np.float64]]]:
    dp = cv2.aruco.DetectorParameters()
    dp.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    cp = cv2.aruco.CharucoParameters()
    cp.minMarkers = 2  # a corner counts only between two found markers
    det = cv2.aruco.CharucoDetector(target.board(), cp, dp)

    def run(grey: NDArray[np.uint8]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        cc, ci, _, _ = det.detectBoard(grey)
        if ci is None or len(ci) == 0:
            return np.zeros(0, np.int64), np.zeros((0, 2))
        cc = np.asarray(cc, np.float32).reshape(-1, 1, 2)
        cc = cv2.cornerSubPix(grey, cc, (5, 5), (-1, -1), _SUBPIX)
        return np.asarray(ci, np.int64).ravel(), np.asarray(cc, np.float64).reshape(-1, 2)

    return run


def _chessboard(target: Chessboard) -> Callable[[NDArray[np.uint8]], tuple[NDArray[np.int64], NDArray[np.float64]]]:
    pattern = (target.columns, target.rows)

    def run(grey: NDArray[np.uint8]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        ok, c = cv2.findChessboardCorners(grey, pattern, None, flags)
        if not ok:
            return np.zeros(0, np.int64), np.zeros((0, 2))
        # the refinement window: a fifth of the corner spacing, so it never reaches the next corner
        grid = np.asarray(c, np.float64).reshape(target.rows, target.columns, 2)
        spacing = float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2)))
        win = target.window or int(max(3, min(11, round(0.2 * spacing))))
        h, w = grey.shape[:2]
        if min(w, h) < 2 * win + 5:  # what cornerSubPix needs, or it raises cv2.error (a traceback)
            raise ParameterError(f"--subpix-window {win}: needs images at least {2 * win + 5} px a side, got {w}x{h}")
        c = cv2.cornerSubPix(grey, np.asarray(c, np.float32), (win, win), (-1, -1), _SUBPIX)
        return np.arange(len(c), dtype=np.int64), np.asarray(c, np.float64).reshape(-1, 2)

    return run


def detect(views: CalibrationViews, target: Target, progress: Callable[[int, int], None] | None = None) -> Observations:
    run = _chessboard(target) if isinstance(target, Chessboard) else _charuco(target)
    items = list(views.items())
    cam, frame, pt, uv = [], [], [], []
    cam_index = {n: i for i, n in enumerate(views.names)}
    frame_index = {f: i for i, f in enumerate(views.frames)}
    for k, (c, f) in enumerate(items):
        img = views.image(c, f)
        if img is not None:
            if (img.shape[1], img.shape[0]) != views.image_size:
                raise CalibrationError(
                    f"{views.source}: camera {c} frame {f} is {img.shape[1]}x{img.shape[0]}, "
                    f"the others {views.image_size[0]}x{views.image_size[1]}"
                )
            ids, corners = run(img)
            cam += [cam_index[c]] * len(ids)
            frame += [frame_index[f]] * len(ids)
            pt.append(ids)
            uv.append(corners)
        if progress:
            progress(k + 1, len(items))
    return Observations(
        np.asarray(cam, np.int64),
        np.asarray(frame, np.int64),
        np.concatenate(pt) if pt else np.zeros(0, np.int64),
        np.concatenate(uv) if uv else np.zeros((0, 2)),
        len(views.names),
        len(views.frames),
    )


class CameraDetections(TypedDict):
    views: int  # frames with any corner of the board
    corners: int


def detections_summary(obs: Observations, names: list[str]) -> dict[str, CameraDetections]:
    v = obs.views()
    return {n: {"views": int((v[i] > 0).sum()), "corners": int(v[i].sum())} for i, n in enumerate(names)}
