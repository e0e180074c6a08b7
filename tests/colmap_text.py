"""COLMAP's text model read back as COLMAP's documentation describes it (doc/format.rst, "Text Format"), and its
cameras evaluated as COLMAP's camera models do (src/colmap/sensor/models.h), with nothing from rigctl: the
tests hold our exporter to this reader, not to itself.

- ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``.
- ``images.txt``: two lines per image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` then ``POINTS2D[]`` as
  ``(X, Y, POINT3D_ID)`` (possibly empty). The pose maps world to camera; the quaternion is Hamilton's (as in
  Eigen), ``w`` first; the camera centre is ``-R^T T``; camera axes x right, y down, z forward.
- ``rigs.txt``: ``RIG_ID NUM_SENSORS REF_SENSOR_TYPE REF_SENSOR_ID`` then, for every other sensor,
  ``SENSOR_TYPE SENSOR_ID HAS_POSE [QW QX QY QZ TX TY TZ]`` (sensor_from_rig).
- ``frames.txt``: ``FRAME_ID RIG_ID QW QX QY QZ TX TY TZ NUM_DATA_IDS`` (rig_from_world), then
  ``SENSOR_TYPE SENSOR_ID DATA_ID`` per data id.
- ``points3D.txt``: ``POINT3D_ID X Y Z R G B ERROR TRACK[]``.
- Pixel coordinates: the top-left corner of the top-left pixel is (0, 0), so its centre is (0.5, 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
# parameter counts of the models a calibration with OpenCV's distortion can be written as
PARAMS = {"PINHOLE": 4, "OPENCV": 8, "FULL_OPENCV": 12}


@dataclass(frozen=True)
class Pose:
    """x_to = R x_from + t."""

    R: F64
    t: F64

    def __matmul__(self, other: Pose) -> Pose:
        return Pose(self.R @ other.R, self.R @ other.t + self.t)

    @property
    def centre(self) -> F64:
        return np.asarray(-self.R.T @ self.t)


@dataclass(frozen=True)
class Camera:
    model: str
    width: int
    height: int
    params: F64

    def project(self, X_cam: F64) -> F64:
        """Pixel of a point in camera coordinates, as COLMAP's model computes it (distortion on the normalised
        image plane, then focal length and principal point)."""
        fx, fy, cx, cy = self.params[:4]
        d = np.zeros(8)
        d[: len(self.params) - 4] = self.params[4:]
        k1, k2, p1, p2, k3, k4, k5, k6 = d
        u, v = X_cam[0] / X_cam[2], X_cam[1] / X_cam[2]
        r2 = u * u + v * v
        radial = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)
        ud = u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u)
        vd = v * radial + 2 * p2 * u * v + p1 * (r2 + 2 * v * v)
        return np.array([fx * ud + cx, fy * vd + cy])


@dataclass(frozen=True)
class Image:
    image_id: int
    pose: Pose  # cam_from_world
    camera_id: int
    name: str
    points2d: list[tuple[float, float, int]]


@dataclass
class Model:
    cameras: dict[int, Camera] = field(default_factory=dict)
    images: dict[str, Image] = field(default_factory=dict)  # by NAME
    rigs: dict[int, tuple[int, dict[int, Pose | None]]] = field(default_factory=dict)  # ref sensor, sensor_from_rig
    # rig, rig_from_world, DATA_ID (the image) by camera SENSOR_ID
    frames: dict[int, tuple[int, Pose, dict[int, int]]] = field(default_factory=dict)
    points3d: dict[int, F64] = field(default_factory=dict)


def rotation(qw: float, qx: float, qy: float, qz: float) -> F64:
    """The rotation matrix of a unit Hamilton quaternion (w, x, y, z)."""
    w, x, y, z = np.array([qw, qx, qy, qz]) / np.linalg.norm([qw, qx, qy, qz])
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _pose(fields: list[str]) -> Pose:
    q = [float(v) for v in fields[:4]]
    assert abs(np.linalg.norm(q) - 1) < 1e-12, f"quaternion {q} is not of unit length"
    return Pose(rotation(*q), np.array([float(v) for v in fields[4:7]]))


def _data_lines(path: Path) -> list[str]:
    return [ln for ln in path.read_text(encoding="utf-8").split("\n")[:-1] if not ln.startswith("#")]


def read_model(folder: Path) -> Model:
    model = Model()
    for ln in _data_lines(folder / "cameras.txt"):
        cam_id, name, w, h, *params = ln.split()
        assert len(params) == PARAMS[name], (name, params)
        model.cameras[int(cam_id)] = Camera(name, int(w), int(h), np.array([float(p) for p in params]))
    lines = _data_lines(folder / "images.txt")
    assert len(lines) % 2 == 0, "images.txt holds two lines per image"
    for head, points in zip(lines[::2], lines[1::2], strict=True):
        f = head.split(" ", 9)
        p = points.split()
        pts = [(float(p[i]), float(p[i + 1]), int(p[i + 2])) for i in range(0, len(p), 3)]
        model.images[f[9]] = Image(int(f[0]), _pose(f[1:8]), int(f[8]), f[9], pts)
    for ln in _data_lines(folder / "rigs.txt"):
        f = ln.split()
        rig_id, n, ref_type, ref_id = int(f[0]), int(f[1]), f[2], int(f[3])
        assert ref_type == "CAMERA"
        sensors: dict[int, Pose | None] = {ref_id: None}
        i = 4
        for _ in range(n - 1):
            assert f[i] == "CAMERA"
            has_pose = f[i + 2] == "1"
            sensors[int(f[i + 1])] = _pose(f[i + 3 : i + 10]) if has_pose else None
            i += 10 if has_pose else 3
        assert i == len(f), f"rigs.txt: {len(f) - i} fields left over"
        model.rigs[rig_id] = (ref_id, sensors)
    for ln in _data_lines(folder / "frames.txt"):
        f = ln.split()
        n = int(f[9])
        data = f[10:]
        assert len(data) == 3 * n and all(data[i] == "CAMERA" for i in range(0, len(data), 3))
        ids = {int(data[i + 1]): int(data[i + 2]) for i in range(0, len(data), 3)}
        model.frames[int(f[0])] = (int(f[1]), _pose(f[2:9]), ids)
    for ln in _data_lines(folder / "points3D.txt"):
        f = ln.split()
        model.points3d[int(f[0])] = np.array([float(v) for v in f[1:4]])
    return model
