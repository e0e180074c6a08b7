"""Calibration exports: OpenCV FileStorage YAML and the COLMAP text model (with ``rigs.txt``/``frames.txt``)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.calibration_model import ArrayCalibration
from rigctl.publish import publish_text


def quaternion(R: NDArray[np.floating]) -> NDArray[np.float64]:
    """(w, x, y, z), Hamilton convention, w >= 0, from a rotation matrix (Shepperd's method: stable everywhere)."""
    m = np.asarray(R, dtype=np.float64)
    tr = np.trace(m)
    cands = [tr, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        s = 2 * np.sqrt(1 + tr)
        q = [s / 4, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif k == 1:
        s = 2 * np.sqrt(1 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif k == 2:
        s = 2 * np.sqrt(1 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2 * np.sqrt(1 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4]
    out = np.asarray(q)
    out /= np.linalg.norm(out)
    return out if out[0] >= 0 else -out


def write_opencv_yaml(calib: ArrayCalibration, path: Path) -> None:
    """One FileStorage file: ``cameras`` (names), and per camera ``<name>_K``, ``_dist``, ``_R``, ``_t``,
    ``_image_size`` (R, t map rig coordinates to the camera's)."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    try:
        fs.write("rig", calib.rig)
        fs.write("reference_camera", calib.reference)
        fs.write("cameras", ",".join(calib.names))
        for n in calib.names:
            cam = calib[n]
            fs.write(f"{n}_K", cam.K)
            fs.write(f"{n}_dist", cam.dist.reshape(1, -1))
            fs.write(f"{n}_R", cam.R)
            fs.write(f"{n}_t", cam.t.reshape(3, 1))
            fs.write(f"{n}_image_size", np.asarray(cam.image_size, dtype=np.int32).reshape(1, 2))
    finally:
        fs.release()


COLMAP_PIXEL_ORIGIN = 0.5  # COLMAP's image coordinate of the top-left pixel's centre (OpenCV's is 0)


def _camera_line(cam_id: int, calib: ArrayCalibration, name: str) -> str:
    cam = calib[name]
    w, h = cam.image_size
    d = np.zeros(8)
    d[: min(8, cam.dist.size)] = cam.dist.ravel()[:8]
    # OpenCV puts the centre of the top-left pixel at (0, 0), COLMAP at (0.5, 0.5): the same ray lands half a
    # pixel further right and down in COLMAP's image coordinates
    fx, fy = cam.K[0, 0], cam.K[1, 1]
    cx, cy = cam.K[0, 2] + COLMAP_PIXEL_ORIGIN, cam.K[1, 2] + COLMAP_PIXEL_ORIGIN
    if np.any(d[4:] != 0):  # k3 and beyond: OpenCV's full model
        params = [fx, fy, cx, cy, d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]]
        model = "FULL_OPENCV"
    else:
        params = [fx, fy, cx, cy, d[0], d[1], d[2], d[3]]
        model = "OPENCV"
    return f"{cam_id} {model} {w} {h} " + " ".join(f"{p:.17g}" for p in params)


def _pose(R: NDArray[np.floating], t: NDArray[np.floating]) -> str:
    return " ".join(f"{v:.17g}" for v in (*quaternion(R), *np.ravel(t)))


def write_colmap(calib: ArrayCalibration, folder: Path, image_ext: str = ".png") -> list[Path]:
    """COLMAP text model: one rig (reference sensor = the reference camera), one camera per array camera, one
    frame of the rig at the origin of rig coordinates, one image per camera named ``<camera><ext>``. Poses
    map world (= rig coordinates) to camera, as ours do."""
    folder.mkdir(parents=True, exist_ok=True)
    names = [calib.reference] + [n for n in calib.names if n != calib.reference]
    ids = {n: i + 1 for i, n in enumerate(names)}
    ref = calib[calib.reference]
    sensors = []
    for n in names[1:]:
        cam = calib[n]
        R = cam.R @ ref.R.T  # sensor_from_rig, where the rig frame is the reference camera's
        t = cam.t - R @ ref.t
        sensors.append(f"CAMERA {ids[n]} 1 {_pose(R, t)}")
    files = {
        "rigs.txt": [
            "# RIG_ID, NUM_SENSORS, REF_SENSOR_TYPE, REF_SENSOR_ID, SENSORS[] as (SENSOR_TYPE, SENSOR_ID, HAS_POSE, "
            "[QW, QX, QY, QZ, TX, TY, TZ])",
            f"1 {len(names)} CAMERA {ids[calib.reference]} " + " ".join(sensors),
        ],
        "cameras.txt": [
            "# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
            *(_camera_line(ids[n], calib, n) for n in names),
        ],
        "frames.txt": [
            "# FRAME_ID, RIG_ID, RIG_FROM_WORLD[QW, QX, QY, QZ, TX, TY, TZ], NUM_DATA_IDS, DATA_IDS[] as "
            "(SENSOR_TYPE, SENSOR_ID, DATA_ID)",
            f"1 1 {_pose(ref.R, ref.t)} {len(names)} " + " ".join(f"CAMERA {ids[n]} {ids[n]}" for n in names),
        ],
        "images.txt": [
            "# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
            "#   POINTS2D[] as (X, Y, POINT3D_ID)",
            *(
                line
                for n in names
                for line in (f"{ids[n]} {_pose(calib[n].R, calib[n].t)} {ids[n]} {n}{image_ext}", "")
            ),
        ],
        "points3D.txt": ["# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"],
    }
    out = []
    for name, lines in files.items():
        path = folder / name
        publish_text(path, "\n".join(lines) + "\n")
        out.append(path)
    return out
