"""The calibration of a camera array and its file, ``calibration.yaml`` (``spec: 1``).

Per camera: ``K`` (3x3), ``dist`` (OpenCV order k1, k2, p1, p2, k3), ``R`` (3x3) and ``t`` (metres) with
X_cam = R @ X_rig + t, and ``image_size`` [width, height]. Rig coordinates: x right, y down, z towards the
scene. ``rigctl calibrate`` writes this file and a simulated take's ``truth/calibration.yaml`` has the
same schema, so the two can be compared field by field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NotRequired, TypedDict

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray

from rigctl.errors import CalibrationError, RigFileError
from rigctl.layout import misspelt
from rigctl.publish import publish_text
from rigctl.rig import CAMERA_NAME, FOCAL_RANGE_WIDTHS
from rigctl.yamlfile import check_spec, line_of, load_yaml_with_lines

CALIBRATION_SPEC = 1
F64 = NDArray[np.float64]


class CameraModelEntry(TypedDict):
    """One camera in ``calibration.yaml``."""

    K: list[list[float]]
    dist: list[float]
    R: list[list[float]]
    t: list[float]
    image_size: list[int]


class CalibrationFile(TypedDict):
    """``calibration.yaml`` as written."""

    spec: int
    rig: str
    reference_camera: str
    cameras: dict[str, CameraModelEntry]
    meta: NotRequired[dict[str, object]]


@dataclass(frozen=True)
class CameraModel:
    """One calibrated camera (pinhole with OpenCV's radial-tangential distortion)."""

    name: str
    K: F64
    dist: F64
    R: F64
    t: F64
    image_size: tuple[int, int]

    @property
    def grid_position(self) -> tuple[int, int]:
        m = CAMERA_NAME.match(self.name)
        if m is None:
            raise RigFileError(f"camera name {self.name!r} is not a grid position r{{row}}c{{col}}")
        return int(m.group(1)), int(m.group(2))

    @property
    def centre(self) -> F64:
        """Camera centre in rig coordinates (metres)."""
        return np.asarray(-self.R.T @ self.t, dtype=np.float64)

    def project(self, points_rig: NDArray[np.floating]) -> F64:
        """Pixel coordinates (N x 2) of rig points (N x 3), with distortion."""
        rvec, _ = cv2.Rodrigues(self.R)
        pts, _ = cv2.projectPoints(
            np.asarray(points_rig, dtype=np.float64).reshape(-1, 1, 3), rvec, self.t, self.K, self.dist
        )
        return np.asarray(pts.reshape(-1, 2), dtype=np.float64)

    def as_dict(self) -> CameraModelEntry:
        return {
            "K": self.K.tolist(),
            "dist": self.dist.ravel().tolist(),
            "R": self.R.tolist(),
            "t": self.t.ravel().tolist(),
            "image_size": list(self.image_size),
        }


@dataclass(frozen=True)
class ArrayCalibration:
    """All cameras of one array, with the reference camera named."""

    rig: str
    cameras: dict[str, CameraModel]
    reference: str
    meta: dict[str, object] = field(default_factory=dict)  # free-form notes kept with the file (its source)

    def __getitem__(self, name: str) -> CameraModel:
        return self.cameras[name]

    @property
    def names(self) -> list[str]:
        return sorted(self.cameras, key=lambda n: self.cameras[n].grid_position)

    def as_dict(self) -> CalibrationFile:
        out: CalibrationFile = {
            "spec": CALIBRATION_SPEC,
            "rig": self.rig,
            "reference_camera": self.reference,
            "cameras": {n: self.cameras[n].as_dict() for n in self.names},
        }
        if self.meta:
            out["meta"] = self.meta
        return out

    def save(self, path: Path) -> None:
        """Published whole (temporary name, fsync, rename, fsync the folder): ``rigctl.publish``."""
        publish_text(path, yaml.safe_dump(self.as_dict(), sort_keys=False, default_flow_style=None))


def _matrix(path: Path, lines: dict[Any, int], loc: tuple[Any, ...], value: Any, shape: tuple[int, ...]) -> F64:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # the last: an integer of hundreds of digits
        arr = None
    if arr is None or (shape and arr.shape != shape) or not np.all(np.isfinite(arr)):
        field_name = ".".join(str(p) for p in loc)
        raise RigFileError(
            f"{path}:{line_of(lines, loc)}: {field_name} must be {'x'.join(map(str, shape)) or 'a list of'} "
            f"finite numbers, got {value!r}"
        )
    return arr


def load_calibration(path: Path) -> ArrayCalibration:
    """Read ``calibration.yaml``; errors name the file, line and field."""
    data, lines = load_yaml_with_lines(path)
    check_spec(path, data, lines, CALIBRATION_SPEC, "calibration")
    cams = data.get("cameras")
    if not isinstance(cams, dict) or not cams:
        raise RigFileError(f"{path}:{line_of(lines, ('cameras',))}: cameras must map camera names to models")
    models: dict[str, CameraModel] = {}
    for name, c in cams.items():
        if wrong := misspelt(name):  # r01c0, r٢c1: named as no grid folder, rig file or take names it
            raise RigFileError(f"{path}:{line_of(lines, ('cameras', name))}: cameras: camera name {name} {wrong}")
        if not isinstance(name, str) or not CAMERA_NAME.match(name):
            raise RigFileError(
                f"{path}:{line_of(lines, ('cameras', name))}: camera name {name!r} is not r{{row}}c{{col}}"
            )
        if not isinstance(c, dict):
            raise RigFileError(f"{path}:{line_of(lines, ('cameras', name))}: cameras.{name} must be a mapping")
        for key in ("K", "dist", "R", "t", "image_size"):
            if key not in c:
                raise RigFileError(f"{path}:{line_of(lines, ('cameras', name))}: cameras.{name}.{key} is required")
        loc = ("cameras", name)
        R = _matrix(path, lines, (*loc, "R"), c["R"], (3, 3))
        if abs(np.linalg.det(R) - 1) > 1e-6 or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
            raise RigFileError(f"{path}:{line_of(lines, (*loc, 'R'))}: cameras.{name}.R is not a rotation matrix")
        size = c["image_size"]
        # at most a take's format side (65,536): a larger integer overflowed the focal length check
        if not (isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and 0 < v <= 65536 for v in size)):
            raise RigFileError(
                f"{path}:{line_of(lines, (*loc, 'image_size'))}: cameras.{name}.image_size must be [width, height], "
                "at most 65536 px a side"
            )
        models[name] = CameraModel(
            name=name,
            K=_matrix(path, lines, (*loc, "K"), c["K"], (3, 3)),
            dist=_matrix(path, lines, (*loc, "dist"), c["dist"], ()).ravel(),
            R=R,
            t=_matrix(path, lines, (*loc, "t"), c["t"], (3,)),
            image_size=(size[0], size[1]),
        )
        problem = camera_problem(models[name])
        if problem:
            field_name, text = problem
            raise CalibrationError(f"{path}:{line_of(lines, (*loc, field_name))}: cameras.{name}.{field_name} {text}")
    names = list(models)
    centres = np.array([models[n].centre for n in names])
    middle = np.median(centres, axis=0)  # the array's middle, which one camera placed far off cannot move
    off = np.linalg.norm(centres - middle, axis=1)
    if not np.all(np.isfinite(off)) or off.max() > MAX_ARRAY_SPAN_M / 2:
        name = names[int(np.nanargmax(np.where(np.isfinite(off), off, np.inf)))]
        raise CalibrationError(
            f"{path}:{line_of(lines, ('cameras', name, 't'))}: cameras.{name} lies {float(off.max()):,.0f} m from "
            f"the array's middle: the cameras of one array lie within {MAX_ARRAY_SPAN_M:g} m of each other"
        )
    ref = data.get("reference_camera", next(iter(models)))
    if not isinstance(ref, str) or ref not in models:
        raise RigFileError(f"{path}:{line_of(lines, ('reference_camera',))}: reference_camera {ref!r} is not a camera")
    meta = data.get("meta") or {}
    if not isinstance(meta, dict):
        raise RigFileError(f"{path}:{line_of(lines, ('meta',))}: meta must be a mapping")
    return ArrayCalibration(rig=str(data.get("rig", "")), cameras=models, reference=ref, meta=meta)


MAX_ARRAY_SPAN_M = 1000.0  # the rig file allows 64 cameras 10 m apart (630 m); a calibration of one array no more

RADIAL_SCALE_RANGE = (0.25, 4.0)  # distorted over undistorted radius anywhere in the image
DIST_LENGTHS = (4, 5, 8, 12, 14)


def radial_scale(dist: F64, r: F64) -> F64:
    """OpenCV's radial factor (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6) at radii ``r``."""
    k = np.zeros(8)
    k[: min(len(dist), 8)] = dist[:8]
    r2 = r * r
    num = 1 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]))
    den = 1 + r2 * (k[5] + r2 * (k[6] + r2 * k[7]))
    with np.errstate(all="ignore"):
        return np.asarray(num / den, dtype=np.float64)


def camera_problem(cam: CameraModel) -> tuple[str, str] | None:
    """What makes no sense in a camera model, as (field, phrase), or None. Checked: focal lengths positive
    and plausible for the image size, principal point inside the image, the distortion's radius growing
    monotonically and within bounds over the image diagonal."""
    w, h = cam.image_size
    K = cam.K
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
        return "K", f"must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got last rows {K[1:].tolist()}"
    lo, hi = FOCAL_RANGE_WIDTHS
    for label, f in (("fx", fx), ("fy", fy)):
        if not lo * w <= f <= hi * w:
            return "K", (
                f"focal length {label} = {f:g} px is not plausible for an image {w} px wide "
                f"(expected {lo * w:g} to {hi * w:g} px)"
            )
    if not (0.5 <= fx / fy <= 2.0):
        return "K", f"fx / fy = {fx / fy:.3g}: pixels this far from square are a mistake"
    if not (0 <= cx <= w and 0 <= cy <= h):
        return "K", f"principal point ({cx:g}, {cy:g}) lies outside the {w}x{h} image"
    if len(cam.dist) not in DIST_LENGTHS:
        return "dist", f"must hold 4, 5, 8, 12 or 14 coefficients (OpenCV order), got {len(cam.dist)}"
    corners = np.array([[0, 0], [w, 0], [0, h], [w, h]], dtype=np.float64)
    r_max = float(np.max(np.hypot((corners[:, 0] - cx) / fx, (corners[:, 1] - cy) / fy)))
    r = np.linspace(0.0, r_max, 256)
    scale = radial_scale(cam.dist, r)
    radius = r * scale
    if not np.all(np.isfinite(scale)) or np.any(np.diff(radius) <= 0):
        bad = int(np.argmax(~np.isfinite(scale[1:]) | (np.diff(radius) <= 0)))
        return "dist", (
            f"{np.round(cam.dist, 6).tolist()} folds the image back on itself at {r[bad + 1] / r_max:.0%} of the "
            "image diagonal (the distorted radius must grow monotonically over the image)"
        )
    lo, hi = RADIAL_SCALE_RANGE
    if not np.all((scale >= lo) & (scale <= hi)):
        worst = float(scale[np.argmax(np.abs(np.log(scale)))])
        return "dist", (
            f"{np.round(cam.dist, 6).tolist()} scales the image radius by {worst:.3g} within the image "
            f"(a lens this model describes stays within {lo:g} to {hi:g})"
        )
    return None


def rotation_angle_deg(R: NDArray[np.floating]) -> float:
    """The angle of a rotation matrix, in degrees (robust near 0 and 180)."""
    rvec, _ = cv2.Rodrigues(np.asarray(R, dtype=np.float64))
    return math.degrees(float(np.linalg.norm(rvec)))
