"""The simulator's ground truth is right: images, disparity and geometry agree with each other."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from rigctl.simulators.array import SimArray
from rigctl.simulators.raycast import Ellipsoid, Rectangle
from rigctl.simulators.settings import SimSettings
from warp_check import STEP, lattice_offsets, mae_against_neighbours

from rigctl.pixfmt import luma, uyvy_to_rgb
from rigctl.rectification.geometry import common_plane
from rigctl.rig import load_rig

RIG = load_rig("sim-3x3")


@pytest.fixture(scope="module")
def ideal() -> SimArray:
    return SimArray(RIG, SimSettings(ideal=True, motion=False))


def test_ideal_take_is_a_perfect_lattice(ideal: SimArray) -> None:
    cal = ideal.calibration
    for name in ideal.names:
        cam = cal[name]
        assert np.allclose(cam.R, np.eye(3)) and not np.any(cam.dist)
        assert np.allclose(cam.K, cal["r0c0"].K)
    grid = ideal.rectified
    assert np.allclose(grid.R, np.eye(3), atol=1e-12)
    assert np.allclose(grid.K, cal["r0c0"].K, atol=1e-9)  # already rectified: nothing to warp
    assert grid.spacing_x_m == pytest.approx(0.12) and grid.spacing_y_m == pytest.approx(0.078)


def test_warping_neighbours_with_true_disparity_reproduces_the_reference(ideal: SimArray) -> None:
    frames = ideal.frames(0)
    disp, _mattes = ideal.truth(0)
    images = {n: luma(frames[i]).astype(np.float32) for i, n in enumerate(ideal.names)}
    disps = dict(zip(ideal.names, disp, strict=True))
    offsets = lattice_offsets(0.078 / 0.12)
    result = mae_against_neighbours(images, disps, offsets)
    for name, (mae, pixels) in result.items():
        assert pixels > 20000, f"{name}: too few comparable pixels"
        assert mae < 2.5, f"{name}: mean absolute error {mae:.2f} grey levels"
    # and the comparison can fail: a disparity 1.5 px off is clearly worse
    off = {n: d + 1.5 for n, d in disps.items()}
    worse = mae_against_neighbours(images, off, offsets)
    assert all(worse[n][0] > result[n][0] + 1.0 for n in STEP), (result, worse)


def test_depth_from_true_disparity_lies_on_the_scene_surfaces(ideal: SimArray) -> None:
    disp, _ = ideal.truth(0)
    cam = ideal.calibration["r1c1"]
    d = disp[ideal.names.index("r1c1")]
    ys, xs = np.nonzero(np.isfinite(d))
    z = cam.K[0, 0] * 0.12 / d[ys, xs]
    x = (xs - cam.K[0, 2]) * z / cam.K[0, 0] + cam.centre[0]
    y = (ys - cam.K[1, 2]) * z / cam.K[1, 1] + cam.centre[1]
    pts = np.stack([x, y, z], axis=1)
    scene = ideal.scene(0)
    dist = np.full(len(pts), np.inf)
    for prim in scene.primitives:
        if not prim.subject:
            continue
        if isinstance(prim, Ellipsoid):
            local = (pts - prim.centre) @ prim.rotation / prim.radii
            r = np.linalg.norm(local, axis=1)
            gap = np.abs(r - 1) * prim.radii.min()
        else:
            assert isinstance(prim, Rectangle)
            gap = np.abs((pts - prim.centre) @ prim.normal)
        dist = np.minimum(dist, gap)
    assert np.median(dist) < 1e-4 and np.percentile(dist, 99) < 1e-3  # metres
    near, far = z.min(), z.max()
    assert near == pytest.approx(2.0, abs=0.05)  # subject_distance_m: the hands
    assert 2.7 < far < 3.0  # the back of the torso, about 0.9 m behind


def test_realistic_truth_is_in_the_rectified_geometry_of_the_true_calibration() -> None:
    arr = SimArray(
        RIG,
        SimSettings(
            motion=False,
            noise=0,
            exposure_spread=0,
            colour_spread=0,
            vignetting=0,
            mount_rotation_deg=0.5,
            mount_position_mm=0.5,
            distortion_k1=-0.08,
        ),
    )
    cal = arr.calibration
    grid = common_plane(cal, RIG.spacing_m)
    frames = arr.frames(0)
    disp, _ = arr.truth(0)
    images, disps = {}, {}
    for i, n in enumerate(arr.names):
        cam = cal[n]
        mx, my = cv2.initUndistortRectifyMap(
            cam.K, cam.dist, grid.rectifying_rotation(cam), grid.K, cam.image_size, cv2.CV_32FC1
        )
        rgb = uyvy_to_rgb(frames[i])
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) * 255
        images[n] = cv2.remap(grey, mx, my, cv2.INTER_LINEAR)
        disps[n] = disp[i]
    # the true positions in the rectified frame, in units of the horizontal spacing
    ref = grid.position_m("r1c1")
    offsets = {n: tuple((grid.position_m(n) - ref)[:2] / grid.spacing_x_m) for n in STEP}
    result = mae_against_neighbours(images, disps, offsets)  # type: ignore[arg-type]
    for name, (mae, pixels) in result.items():
        assert pixels > 15000
        assert mae < 3.0, f"{name}: mean absolute error {mae:.2f} after rectification"
    # the raw (unrectified) images do not line up with the truth: rectification is needed
    raw = {n: luma(frames[i]).astype(np.float32) for i, n in enumerate(arr.names)}
    unrect = mae_against_neighbours(raw, disps, offsets)  # type: ignore[arg-type]
    assert np.mean([v[0] for v in unrect.values()]) > 2 * np.mean([v[0] for v in result.values()])


def test_same_seed_same_bytes_different_seed_differs() -> None:
    a = SimArray(RIG, SimSettings(seed=5, motion=False))
    b = SimArray(RIG, SimSettings(seed=5, motion=False))
    c = SimArray(RIG, SimSettings(seed=6, motion=False))
    fa, fb, fc = a.frames(0), b.frames(0), c.frames(0)
    assert all(np.array_equal(x, y) for x, y in zip(fa, fb, strict=True))
    assert all(np.array_equal(x, y) for x, y in zip(a._noise, b._noise, strict=True))
    assert not any(np.array_equal(x, y) for x, y in zip(fa, fc, strict=True))
    assert not np.allclose(a.calibration["r0c0"].K, c.calibration["r0c0"].K)


def test_charuco_is_detected_everywhere_with_accurate_corners() -> None:
    arr = SimArray(RIG, SimSettings(scene="charuco", ideal=True, board_poses=12, seed=1))
    detector = cv2.aruco.CharucoDetector(arr.board.board())
    obj = arr.board.corners_m()
    seen = dict.fromkeys(arr.names, 0)
    errors = []
    for state in range(arr.distinct_states):
        frames = arr.frames(state)
        pose = arr.board_poses[state]
        for i, n in enumerate(arr.names):
            grey = luma(frames[i])
            corners, ids, _, _ = detector.detectBoard(grey)
            if ids is None or len(ids) < 6:
                continue
            seen[n] += 1
            ids = ids.ravel()
            refined = cv2.cornerSubPix(
                grey,
                corners.reshape(-1, 1, 2).astype(np.float32),
                (4, 4),
                (-1, -1),
                (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-5),
            )
            truth = arr.calibration[n].project(pose.origin + obj[ids] @ pose.R.T)
            errors.extend(np.linalg.norm(refined.reshape(-1, 2) - truth, axis=1))
    assert all(v >= 0.8 * arr.distinct_states for v in seen.values()), seen
    err = np.asarray(errors)
    assert np.median(err) < 0.06 and np.percentile(err, 90) < 0.1, (np.median(err), np.percentile(err, 90))


def test_charuco_poses_are_varied() -> None:
    arr = SimArray(RIG, SimSettings(scene="charuco", board_poses=40))
    poses = arr.board_poses
    z = np.array([p.origin[2] for p in poses])
    tilt = np.degrees([np.arccos(p.R[2, 2]) for p in poses])
    assert z.min() < 2.0 and z.max() > 2.9
    assert tilt.max() > 30 and tilt.max() <= 40.5
    # some poses leave the board partly outside some camera's view
    partial = 0
    for p in poses:
        corners = p.origin + np.array([[0, 0, 0], [0.6, 0, 0], [0, 0.45, 0], [0.6, 0.45, 0]]) @ p.R.T
        for n in arr.names:
            uv = arr.calibration[n].project(corners)
            if np.any((uv[:, 0] < 0) | (uv[:, 0] > RIG.width_px) | (uv[:, 1] < 0) | (uv[:, 1] > RIG.height_px)):
                partial += 1
                break
    assert partial >= 3
