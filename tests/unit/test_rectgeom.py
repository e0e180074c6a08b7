"""Common-plane rectification geometry: the ideal grid is left alone, rotations are removed, swaps refused."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from rigctl.calibration_model import ArrayCalibration, CameraModel
from rigctl.errors import CalibrationError
from rigctl.rectification.geometry import common_plane


def grid(rot_deg: float = 0.0, swap: bool = False, seed: int = 0, w: int = 960, h: int = 540) -> ArrayCalibration:
    rng = np.random.default_rng(seed)
    K = np.array([[1838.0, 0, (w - 1) / 2], [0, 1838.0, (h - 1) / 2], [0, 0, 1]])
    cams = {}
    names = [f"r{r}c{c}" for r in range(3) for c in range(3)]
    for name in names:
        r, c = int(name[1]), int(name[3])
        centre = np.array([(c - 1) * 0.12, (r - 1) * 0.078, 0.0])
        R = cv2.Rodrigues(np.radians(rot_deg) * rng.normal(size=3))[0]
        cams[name] = CameraModel(name, K, np.zeros(5), R, -R @ centre, (w, h))
    if swap:
        a, b = cams["r0c0"], cams["r0c2"]
        cams["r0c0"] = CameraModel("r0c0", a.K, a.dist, b.R, b.t, a.image_size)
        cams["r0c2"] = CameraModel("r0c2", b.K, b.dist, a.R, a.t, b.image_size)
    return ArrayCalibration("test", cams, "r1c1")


def test_ideal_grid_is_its_own_rectification() -> None:
    g = common_plane(grid())
    assert np.allclose(g.R, np.eye(3))
    assert np.allclose(g.K, grid()["r0c0"].K)
    assert g.spacing_x_m == pytest.approx(0.12) and g.spacing_y_m == pytest.approx(0.078)
    assert g.lattice_residual_m == pytest.approx(0.0, abs=1e-12)


def test_rotated_cameras_share_rows_after_rectification() -> None:
    cal = grid(rot_deg=1.0, seed=3)
    g = common_plane(cal)
    point = np.array([[0.05, -0.02, 2.5]])
    rows = {}
    for name in cal.names:
        cam = cal[name]
        raw = cam.project(point).reshape(1, 1, 2)
        rect = cv2.undistortPoints(raw, cam.K, cam.dist, R=g.rectifying_rotation(cam), P=g.K).reshape(2)
        rows[name] = rect
    for r in range(3):
        ys = [rows[f"r{r}c{c}"][1] for c in range(3)]
        assert max(ys) - min(ys) < 1e-6  # same row in every camera of a grid row
    for c in range(3):
        xs = [rows[f"r{r}c{c}"][0] for r in range(3)]
        assert max(xs) - min(xs) < 1e-6  # same column down a grid column
    d = rows["r1c1"][0] - rows["r1c2"][0]
    assert d == pytest.approx(g.focal_px * 0.12 / 2.5, rel=1e-6)  # d = f * dx / Z
    # every rectified image is fully covered: the shared matrix zooms in just enough
    assert g.focal_px > 1838.0


def test_swapped_cameras_are_an_error_not_a_flipped_image() -> None:
    with pytest.raises(CalibrationError, match="camera order does not match the geometry"):
        common_plane(grid(swap=True))
