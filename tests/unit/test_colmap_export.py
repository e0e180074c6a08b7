"""The calibration exports read back by readers we did not write for the exporter, and compared with what they
were made from: a calibration built here from the rig file (its K, picture size and camera offsets) with a
rotation for every camera and for the whole rig.

COLMAP (``tests/colmap_text.py``, after COLMAP's documentation): camera models and intrinsics, each image's
world-to-camera pose and the camera centre it implies, the rig and frame that compose to the same pose, and the
pixel a 3D point lands on. OpenCV puts the centre of the top-left pixel at (0, 0), COLMAP at (0.5, 0.5): the
same ray is half a pixel further right and down in COLMAP's coordinates, and names the same pixel.
OpenCV FileStorage: read by OpenCV's own reader, every field of every camera.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from colmap_text import Pose, read_model  # type: ignore[import-not-found]

from rigctl.calib.export import write_colmap, write_opencv_yaml
from rigctl.calibration_model import ArrayCalibration, CameraModel
from rigctl.rig import Rig, load_rig

# the whole rig turned and moved in the world: X_rig = RIG_R @ X_world + RIG_T
RIG_R = cv2.Rodrigues(np.radians([8.0, -23.0, 4.0]))[0]
RIG_T = np.array([0.4, -1.2, 3.0])
# points 1.7 to 4.2 m in front of the rig, in rig coordinates, and in the world's
POINTS = np.array([[0.31, -0.12, 2.5], [-0.4, 0.2, 3.1], [0.0, 0.0, 1.7], [0.05, 0.033, 4.2], [0.6, 0.4, 2.2]])
WORLD_POINTS = (RIG_R.T @ (POINTS - RIG_T).T).T


def expected_centre(rig: Rig, name: str) -> np.ndarray:
    """Where the rig file puts a camera, in world coordinates: its offset in the rig, moved with the rig."""
    cam = rig.camera(name)
    return RIG_R.T @ (np.array([cam.x_m, cam.y_m, 0.0]) - RIG_T)


def calibration(full_model_camera: str | None = None) -> tuple[Rig, ArrayCalibration]:
    """Every camera of the simulated rig at its offset, each turned by its own few degrees, with the rig's focal
    length, the picture size and its centre ((w - 1) / 2 in OpenCV's convention) moved by a few pixels, and
    distortion; ``full_model_camera`` also gets k3..k6 (COLMAP's FULL_OPENCV)."""
    rig = load_rig("sim-3x3")
    w, h = rig.width_px, rig.height_px
    rng = np.random.default_rng(5)
    cams = {}
    for cam in rig.cameras:
        K = np.array(
            [
                [rig.c0_px * (1 + 0.01 * rng.normal()), 0, (w - 1) / 2 + 3 * rng.normal()],
                [0, rig.c0_y_px * (1 + 0.01 * rng.normal()), (h - 1) / 2 + 3 * rng.normal()],
                [0, 0, 1],
            ]
        )
        dist = np.array([-0.08, 0.03, 0.0004, -0.0003, 0.0]) * (1 + 0.1 * rng.normal(size=5))
        if cam.name == full_model_camera:
            dist = np.array([-0.08, 0.03, 0.0004, -0.0003, 0.002, 0.001, -0.0005, 0.0002])
        R_cam = cv2.Rodrigues(np.radians(2.0) * rng.normal(size=3))[0]  # camera from its mount in the rig
        C = np.array([cam.x_m, cam.y_m, 0.0])
        R = R_cam @ RIG_R
        t = -R_cam @ C + R_cam @ RIG_T
        cams[cam.name] = CameraModel(cam.name, K, dist, R, t, (w, h))
    return rig, ArrayCalibration(rig.name, cams, "r1c1")


@pytest.mark.parametrize("full_model_camera", [None, "r0c2"])
def test_colmap_model_reads_back_as_the_rig(tmp_path: Path, full_model_camera: str | None) -> None:
    rig, cal = calibration(full_model_camera)
    write_colmap(cal, tmp_path)
    model = read_model(tmp_path)
    assert sorted(model.images) == sorted(f"{n}.png" for n in rig.camera_names)
    assert model.points3d == {}
    for name in rig.camera_names:
        image = model.images[f"{name}.png"]
        cam, K = model.cameras[image.camera_id], cal[name].K
        # camera model and intrinsics: the rig's picture size, K with COLMAP's pixel origin, the distortion
        assert cam.model == ("FULL_OPENCV" if name == full_model_camera else "OPENCV")
        assert (cam.width, cam.height) == (rig.width_px, rig.height_px)
        assert cam.params[:4] == pytest.approx([K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5], abs=1e-12)
        dist = np.zeros(8)
        dist[: cal[name].dist.size] = cal[name].dist.ravel()
        n = len(cam.params) - 4  # OPENCV: k1 k2 p1 p2; FULL_OPENCV: and k3..k6
        assert cam.params[4:] == pytest.approx(dist[:n], abs=1e-15) and not dist[n:].any()
        # the pose: world to camera, whose centre is where the rig file puts the camera
        assert np.allclose(image.pose.R, cal[name].R, atol=1e-12)
        assert np.allclose(image.pose.centre, expected_centre(rig, name), atol=1e-12)
    # the rig (reference sensor r1c1) and its one frame compose to every image's pose
    ((rig_id, frame_pose, data_ids),) = model.frames.values()
    ref, sensors = model.rigs[rig_id]
    assert model.images["r1c1.png"].camera_id == ref
    assert sorted(sensors) == sorted(data_ids) == sorted(model.cameras)
    for image in model.images.values():
        assert data_ids[image.camera_id] == image.image_id
        sensor_from_rig = sensors[image.camera_id] or Pose(np.eye(3), np.zeros(3))
        composed = sensor_from_rig @ frame_pose
        assert np.allclose(composed.R, image.pose.R, atol=1e-12) and np.allclose(composed.t, image.pose.t, atol=1e-12)


def test_a_point_projects_to_the_same_pixel_in_opencv_and_colmap(tmp_path: Path) -> None:
    rig, cal = calibration("r2c0")
    write_colmap(cal, tmp_path)
    model = read_model(tmp_path)
    fractions = []
    for name in rig.camera_names:
        image = model.images[f"{name}.png"]
        cam = model.cameras[image.camera_id]
        opencv = cal[name].project(WORLD_POINTS)  # K [R | t] with distortion, through cv2.projectPoints
        for X, cv in zip(WORLD_POINTS, opencv, strict=True):
            colmap = cam.project(image.pose.R @ X + image.pose.t)
            # the two conventions differ by exactly half a pixel on both axes ...
            assert np.allclose(colmap - cv, 0.5, atol=1e-9), (name, X, cv, colmap)
            # ... so both name the same pixel: OpenCV's nearest integer, COLMAP's floor
            assert [round(c) for c in cv] == [math.floor(c) for c in colmap]
            fractions.extend(c - math.floor(c) for c in cv)
    # the points include positions in the right half of a pixel, where an unshifted export names the neighbour
    assert any(f > 0.5 for f in fractions) and any(f < 0.5 for f in fractions)


def test_opencv_yaml_reads_back_in_opencv(tmp_path: Path) -> None:
    rig, cal = calibration("r0c2")
    path = tmp_path / "cv.yaml"
    write_opencv_yaml(cal, path)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        assert fs.getNode("rig").string() == rig.name and fs.getNode("reference_camera").string() == "r1c1"
        assert fs.getNode("cameras").string().split(",") == rig.camera_names
        for name in rig.camera_names:
            K, dist = fs.getNode(f"{name}_K").mat(), fs.getNode(f"{name}_dist").mat()
            R, t = fs.getNode(f"{name}_R").mat(), fs.getNode(f"{name}_t").mat()
            size = fs.getNode(f"{name}_image_size").mat()
            assert np.array_equal(K, cal[name].K) and np.array_equal(dist.ravel(), cal[name].dist.ravel())
            assert np.array_equal(R, cal[name].R) and np.array_equal(t.ravel(), cal[name].t)
            assert t.shape == (3, 1) and size.ravel().tolist() == [rig.width_px, rig.height_px]
            assert np.allclose(-R.T @ t.ravel(), expected_centre(rig, name), atol=1e-12)
            pixels, _ = cv2.projectPoints(WORLD_POINTS, cv2.Rodrigues(R)[0], t, K, dist)
            assert np.allclose(pixels.reshape(-1, 2), cal[name].project(WORLD_POINTS), atol=1e-9)
    finally:
        fs.release()
