"""The COLMAP export's pixel convention: the same 3D point lands on the same pixel in both programs.

OpenCV puts the centre of the top-left pixel at (0, 0); COLMAP at (0.5, 0.5). The test projects known
points through OpenCV (the calibration as we hold it) and through COLMAP's OPENCV camera model as COLMAP
evaluates it from the exported text files, and compares.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from rigctl.calib.export import write_colmap
from rigctl.calibration_model import ArrayCalibration, CameraModel


def _calibration() -> ArrayCalibration:
    K = np.array([[1400.0, 0, 958.3], [0, 1401.0, 541.7], [0, 0, 1]])
    dist = np.array([-0.08, 0.03, 0.0004, -0.0003, 0.0])
    cams = {}
    for i, name in enumerate(("r0c0", "r0c1")):
        R, _ = np.eye(3), None
        t = np.array([-0.06 * i, 0.0, 0.0])
        cams[name] = CameraModel(name, K.copy(), dist.copy(), R, t, (1920, 1080))
    return ArrayCalibration("test", cams, "r0c0")


def _colmap_project(camera_line: str, image_line: str, X: np.ndarray) -> np.ndarray:
    """COLMAP's OPENCV model (src/colmap/sensor/models.h): world -> camera with the image's pose, then
    distortion on normalised coordinates, then u = fx * x + cx."""
    p = camera_line.split()
    assert p[1] == "OPENCV"
    fx, fy, cx, cy, k1, k2, p1, p2 = (float(v) for v in p[4:12])
    q = [float(v) for v in image_line.split()[1:8]]
    w, x, y, z, tx, ty, tz = q
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    Xc = R @ X + np.array([tx, ty, tz])
    u, v = Xc[0] / Xc[2], Xc[1] / Xc[2]
    r2 = u * u + v * v
    radial = k1 * r2 + k2 * r2 * r2
    du = u * radial + 2 * p1 * u * v + p2 * (r2 + 2 * u * u)
    dv = v * radial + 2 * p2 * u * v + p1 * (r2 + 2 * v * v)
    return np.array([fx * (u + du) + cx, fy * (v + dv) + cy])


def test_a_point_projects_to_the_same_pixel_in_opencv_and_colmap(tmp_path: Path) -> None:
    cal = _calibration()
    write_colmap(cal, tmp_path)
    cameras = [ln for ln in (tmp_path / "cameras.txt").read_text().splitlines() if not ln.startswith("#")]
    images = [ln for ln in (tmp_path / "images.txt").read_text().splitlines() if ln and not ln.startswith("#")]
    by_name = {ln.split()[-1].removesuffix(".png"): ln for ln in images}
    cam_line = {ln.split()[0]: ln for ln in cameras}
    points = np.array([[0.31, -0.12, 2.5], [-0.4, 0.2, 3.1], [0.0, 0.0, 1.7], [0.05, 0.033, 4.2]])
    fractions = []
    for name in cal.names:
        img = by_name[name]
        for X in points:
            cv = cal[name].project(X[None])[0]
            colmap = _colmap_project(cam_line[img.split()[8]], img, X)
            # the two conventions differ by exactly half a pixel on both axes ...
            assert np.allclose(colmap - cv, 0.5, atol=1e-9), (name, X, cv, colmap)
            # ... so both name the same pixel: OpenCV's nearest integer, COLMAP's floor
            assert [round(c) for c in cv] == [math.floor(c) for c in colmap]
            fractions.extend(c - math.floor(c) for c in cv)
    # the points include positions in the right half of a pixel, where the unshifted export names the
    # neighbouring pixel
    assert any(f > 0.5 for f in fractions) and any(f < 0.5 for f in fractions)
