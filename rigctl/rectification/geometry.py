"""Common-plane grid rectification geometry: one rotation and one camera matrix for the whole array.

All cameras are turned to one orientation whose x axis runs along the grid's rows and y axis along its
columns (fitted to the camera centres), and share one camera matrix, so that a point lies on the same
row in horizontal neighbours and the same column in vertical neighbours. The shared matrix is chosen so
that every camera's rectified image is fully covered by valid pixels.

This module is the single definition of the rectified geometry: ``rigctl rectify`` warps images into it,
and the simulator computes its ground-truth disparity in it from the true calibration.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import cv2
import numpy as np

from rigctl.calibration_model import F64, ArrayCalibration, CameraModel
from rigctl.errors import CalibrationError
from rigctl.take.manifest import Rectification

_BORDER_SAMPLES = 64


@dataclass(frozen=True)
class RectifiedGrid:
    """The rectified array: shared rotation ``R`` (rig -> rectified), shared ``K``, per-camera centres."""

    R: F64
    K: F64
    image_size: tuple[int, int]
    centres: dict[str, F64]
    grid: dict[str, tuple[int, int]]
    spacing_x_m: float
    spacing_y_m: float
    lattice_residual_m: float

    @property
    def focal_px(self) -> float:
        return float(self.K[0, 0])

    def camera(self, name: str) -> CameraModel:
        """The rectified (distortion-free) camera at ``name``'s true centre."""
        c = self.centres[name]
        return CameraModel(name, self.K.copy(), np.zeros(5), self.R.copy(), -self.R @ c, self.image_size)

    def position_m(self, name: str) -> F64:
        """Camera centre in rectified coordinates (x right, y down), relative to the grid's fitted origin."""
        return np.asarray(self.R @ self.centres[name], dtype=np.float64)

    def disparity_from_depth(self, depth_m: F64) -> F64:
        """Disparity for the horizontal spacing at rectified depth Z: d = f * dx / Z (0 at infinity)."""
        with np.errstate(divide="ignore"):
            return np.asarray(self.focal_px * self.spacing_x_m / depth_m, dtype=np.float64)

    def rectifying_rotation(self, cam: CameraModel) -> F64:
        """Rotation from ``cam``'s own coordinates to the rectified ones (for initUndistortRectifyMap)."""
        return np.asarray(self.R @ cam.R.T, dtype=np.float64)


def _unit(v: F64) -> F64:
    n = float(np.linalg.norm(v))
    if not n > 0:
        raise CalibrationError("degenerate camera layout: cannot find the grid's axes")
    return np.asarray(v / n, dtype=np.float64)


def _fit_lattice(calib: ArrayCalibration) -> tuple[F64, F64 | None, F64 | None, float, dict[str, tuple[int, int]]]:
    names = calib.names
    pos = {n: calib[n].grid_position for n in names}
    rows = {p[0] for p in pos.values()}
    cols = {p[1] for p in pos.values()}
    design = [
        [1.0] + ([float(pos[n][1])] if len(cols) > 1 else []) + ([float(pos[n][0])] if len(rows) > 1 else [])
        for n in names
    ]
    A = np.asarray(design)
    C = np.stack([calib[n].centre for n in names])
    coef, *_ = np.linalg.lstsq(A, C, rcond=None)
    resid = C - A @ coef
    worst = float(np.max(np.linalg.norm(resid, axis=1))) if len(names) else 0.0
    k = 1
    a = b = None
    if len(cols) > 1:
        a = coef[k]
        k += 1
    if len(rows) > 1:
        b = coef[k]
    return coef[0], a, b, worst, pos


def common_plane(calib: ArrayCalibration, nominal_spacing_m: tuple[float, float] | None = None) -> RectifiedGrid:
    """The rectified geometry of ``calib``: shared rotation and camera matrix, valid everywhere.

    Raises :class:`CalibrationError` when camera order and geometry disagree (e.g. two cameras swapped:
    their centres no longer fit a lattice, or the grid's axes point against the cameras' own).
    """
    names = calib.names
    _, a, b, worst, pos = _fit_lattice(calib)
    mean_x = _unit(np.mean([calib[n].R[0] for n in names], axis=0))
    mean_y = _unit(np.mean([calib[n].R[1] for n in names], axis=0))
    mean_z = _unit(np.mean([calib[n].R[2] for n in names], axis=0))
    if a is not None:
        x = _unit(a)
        if b is not None:
            z = _unit(np.cross(a, b))
            y = np.cross(z, x)
        else:
            y = _unit(mean_y - (mean_y @ x) * x)
            z = np.cross(x, y)
    elif b is not None:
        y = _unit(b)
        x = _unit(mean_x - (mean_x @ y) * y)
        z = np.cross(x, y)
    else:
        x, y, z = mean_x, mean_y, mean_z
    if z @ mean_z < 0.5 or x @ mean_x < 0.5:
        raise CalibrationError(
            "camera order does not match the geometry: the grid fitted to the camera centres runs against "
            "the cameras' own axes (are two cameras swapped, or the rig mirrored?)"
        )
    sx = float(np.linalg.norm(a)) if a is not None else (nominal_spacing_m or (1.0, 1.0))[0]
    sy = float(np.linalg.norm(b)) if b is not None else (nominal_spacing_m or (sx, sx))[1]
    spacing = min(sx if a is not None else np.inf, sy if b is not None else np.inf)
    if np.isfinite(spacing) and worst > 0.25 * spacing:
        far_off = max(names, key=lambda n: float(np.linalg.norm(calib[n].centre - _predicted(calib, n, a, b))))
        raise CalibrationError(
            f"camera {far_off} is {worst * 1e3:.0f} mm off the grid fitted to all camera centres "
            f"(spacing {spacing * 1e3:.0f} mm): camera order does not match the geometry (swapped cameras?)"
        )
    R = np.stack([x, y, z])
    K, size = _shared_matrix(calib, R)
    return RectifiedGrid(
        R=R,
        K=K,
        image_size=size,
        centres={n: calib[n].centre for n in names},
        grid=pos,
        spacing_x_m=sx,
        spacing_y_m=sy,
        lattice_residual_m=worst,
    )


def _predicted(calib: ArrayCalibration, name: str, a: F64 | None, b: F64 | None) -> F64:
    names = calib.names
    origin = np.mean([calib[n].centre for n in names], axis=0)
    rows = np.mean([calib[n].grid_position[0] for n in names])
    cols = np.mean([calib[n].grid_position[1] for n in names])
    r, c = calib[name].grid_position
    out = origin.copy()
    if a is not None:
        out += (c - cols) * a
    if b is not None:
        out += (r - rows) * b
    return np.asarray(out, dtype=np.float64)


def _border(w: int, h: int) -> dict[str, F64]:
    s = np.linspace(0.0, 1.0, _BORDER_SAMPLES)
    return {
        "left": np.stack([np.zeros_like(s), s * (h - 1)], axis=1),
        "right": np.stack([np.full_like(s, w - 1.0), s * (h - 1)], axis=1),
        "top": np.stack([s * (w - 1), np.zeros_like(s)], axis=1),
        "bottom": np.stack([s * (w - 1), np.full_like(s, h - 1.0)], axis=1),
    }


def _shared_matrix(calib: ArrayCalibration, R: F64) -> tuple[F64, tuple[int, int]]:
    """Shared K: mean focal length, zoomed and centred on the area every camera covers after rotation."""
    names = calib.names
    sizes = {calib[n].image_size for n in names}
    if len(sizes) != 1:
        raise CalibrationError(f"cameras have different image sizes {sorted(sizes)}: cannot share one matrix")
    (w, h) = sizes.pop()
    f = float(np.mean([(calib[n].K[0, 0] + calib[n].K[1, 1]) / 2 for n in names]))
    left = top = -np.inf
    right = bottom = np.inf
    for n in names:
        cam = calib[n]
        rot = R @ cam.R.T
        for side, pts in _border(w, h).items():
            norm = cv2.undistortPoints(pts.reshape(-1, 1, 2), cam.K, cam.dist).reshape(-1, 2)
            rays = np.column_stack([norm, np.ones(len(norm))]) @ rot.T
            if np.any(rays[:, 2] <= 0):
                raise CalibrationError(f"camera {n} looks away from the array's common direction")
            xy = f * rays[:, :2] / rays[:, 2:3]
            if side == "left":
                left = max(left, float(xy[:, 0].max()))
            elif side == "right":
                right = min(right, float(xy[:, 0].min()))
            elif side == "top":
                top = max(top, float(xy[:, 1].max()))
            else:
                bottom = min(bottom, float(xy[:, 1].min()))
    if not (right > left and bottom > top):
        raise CalibrationError("the cameras' rectified views have no area in common")
    s = max((w - 1) / (right - left), (h - 1) / (bottom - top))
    cx = (w - 1) / 2 - s * (left + right) / 2
    cy = (h - 1) / 2 - s * (top + bottom) / 2
    K = np.array([[f * s, 0, cx], [0, f * s, cy], [0, 0, 1]], dtype=np.float64)
    return K, (w, h)


def calibration_hash(calib: ArrayCalibration) -> str:
    """SHA-256 of the calibration's numbers (not its file's formatting)."""
    data = {n: calib[n].as_dict() for n in calib.names}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def rectification_record(
    calib: ArrayCalibration, grid: RectifiedGrid | None = None, calibration: str | None = None
) -> Rectification:
    """The manifest's rectification section for frames in ``calib``'s common plane (``grid``, when it is
    built already): what depth reads (positions, focal length, spacing)."""
    g = grid if grid is not None else common_plane(calib)
    return Rectification(
        calibration_sha256=calibration_hash(calib),
        R=g.R.tolist(),
        K=g.K.tolist(),
        image_size=list(g.image_size),
        spacing_x_m=g.spacing_x_m,
        spacing_y_m=g.spacing_y_m,
        focal_px=g.focal_px,
        lattice_residual_mm=g.lattice_residual_m * 1e3,
        positions_m={n: g.position_m(n).tolist() for n in calib.names},
        calibration=calibration,
    )
