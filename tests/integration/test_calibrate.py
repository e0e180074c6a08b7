"""``rigctl calibrate`` on real images (OpenCV's stereo chessboard pairs) and on simulated ChArUco takes with
realistic mounting errors, distortion and noise, against the truth; and takes that cannot constrain a
calibration, which must end with a diagnosis naming the camera and what to shoot."""

from __future__ import annotations

import dataclasses
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from colmap_text import Pose, read_model  # type: ignore[import-not-found]
from conftest import SHARED
from tests_support import run_rigctl

from rigctl.board import BoardSpec
from rigctl.calibration_model import load_calibration

STEREO = SHARED / "data" / "opencv-stereo-chessboard"


def record(out: Path, name: str, frames: int, *sim: str) -> Path:
    """A board take on the simulated clock: every pose is recorded however busy the machine is (a live take
    on a loaded machine loses frames at the source, and with them the views these tests count)."""
    args = ["record", "--take", name, "--scene", "charuco", "--frames", str(frames), "--out", str(out)]
    sim = ("deterministic=true", f"board_poses={frames}", *sim)
    res = run_rigctl(*args, *[a for s in sim for a in ("--sim", s)])
    assert res.returncode == 0, res.stderr
    return out / name


def calibrate(*args: str) -> tuple[int, dict, str]:  # type: ignore[type-arg]
    res = run_rigctl("calibrate", *args, "--json", timeout=600)
    report = json.loads(res.stdout) if res.stdout.strip() else {}
    return res.returncode, report, res.stderr


# ---- real images -------------------------------------------------------------------------------------------
def test_real_stereo_pairs_flag_pair_02(tmp_path: Path) -> None:
    """With OpenCV's sample detection (an 11 px refinement window), pair 02 is the outlier REFERENCE.md names."""
    code, rep, err = calibrate(
        str(STEREO), "--chessboard", "9x6", "--subpix-window", "11", "--out", str(tmp_path / "c.yaml")
    )
    assert code == 0, err
    assert "02" in rep["frames_with_rejected_views"]
    assert sorted(rep["frames_with_rejected_views"]) == ["02"]  # and nothing else
    assert rep["rms_px"] <= 0.45
    residual = rep["rectification_residuals"]["vertical_between_horizontal_neighbours"]["raw"]
    assert residual["n"] > 100 and residual["rms"] <= 0.2
    assert rep["cameras"]["r0c0"]["input_name"] == "left"
    cal = load_calibration(tmp_path / "c.yaml")
    baseline = np.linalg.norm(cal["r0c0"].centre - cal["r0c1"].centre)
    assert 3.0 < baseline < 3.6  # in squares: the sample's stereo baseline is about 3.3 squares


def test_real_stereo_pairs_with_the_adaptive_window(tmp_path: Path) -> None:
    """Our default refinement window (a fifth of the corner spacing) does not drag corners to the board's
    edge: no view is an outlier and the error halves."""
    code, rep, err = calibrate(str(STEREO), "--chessboard", "9x6", "--out", str(tmp_path / "c.yaml"))
    assert code == 0, err
    assert rep["rejected_views"] == [] and rep["rms_px"] < 0.25


def test_real_stereo_exports_read_back_as_the_calibration(tmp_path: Path) -> None:
    """--colmap and --opencv hold what calibration.yaml of the same run holds, read back by COLMAP's documented
    text format (tests/colmap_text.py) and by OpenCV's FileStorage: K and size, each camera's pose and centre,
    the rig and frame composing to each pose, and a point on the same pixel (COLMAP's coordinates half a pixel
    on from OpenCV's)."""
    out = tmp_path / "c.yaml"
    colmap, opencv = tmp_path / "colmap", tmp_path / "cv.yaml"
    code, _, err = calibrate(
        str(STEREO), "--chessboard", "9x6", "--out", str(out), "--colmap", str(colmap), "--opencv", str(opencv)
    )
    assert code == 0, err
    cal = load_calibration(out)
    model = read_model(colmap)
    ((rig_id, rig_from_world, _),) = model.frames.values()
    ref, sensors = model.rigs[rig_id]
    fs = cv2.FileStorage(str(opencv), cv2.FILE_STORAGE_READ)
    for name in cal.names:
        c, image = cal[name], model.images[f"{name}.png"]
        cam = model.cameras[image.camera_id]
        assert (cam.model, (cam.width, cam.height)) == ("OPENCV", c.image_size)
        assert cam.params == pytest.approx([*np.diag(c.K)[:2], *(c.K[:2, 2] + 0.5), *c.dist[:4]], rel=1e-15)
        assert np.allclose(image.pose.R, c.R, atol=1e-12) and np.allclose(image.pose.centre, c.centre, atol=1e-12)
        composed = (sensors[image.camera_id] or Pose(np.eye(3), np.zeros(3))) @ rig_from_world
        assert np.allclose(composed.R, c.R, atol=1e-12) and np.allclose(composed.t, c.t, atol=1e-12)
        X = c.centre + c.R.T @ np.array([1.3, -0.9, 20.0])  # 20 squares ahead, towards the picture's corner
        assert np.allclose(cam.project(image.pose.R @ X + image.pose.t) - c.project(X[None])[0], 0.5, atol=1e-9)
        for key, value in (("K", c.K), ("dist", c.dist[None]), ("R", c.R), ("t", c.t[:, None])):
            assert np.array_equal(fs.getNode(f"{name}_{key}").mat(), value), (name, key)
        assert fs.getNode(f"{name}_image_size").mat().ravel().tolist() == list(c.image_size)
    fs.release()
    assert model.images[f"{cal.reference}.png"].camera_id == ref


def test_board_in_millimetres_gives_the_same_result(tmp_path: Path) -> None:
    """OpenCV 5's multiview calibration calls a board in millimetres "collinear"; we scale it."""
    _, squares, _ = calibrate(str(STEREO), "--chessboard", "9x6", "--out", str(tmp_path / "a.yaml"))
    code, mm, err = calibrate(str(STEREO), "--chessboard", "9x6", "--square", "25", "--out", str(tmp_path / "b.yaml"))
    assert code == 0, err
    assert mm["rms_px"] == pytest.approx(squares["rms_px"], abs=1e-4)
    a, b = load_calibration(tmp_path / "a.yaml"), load_calibration(tmp_path / "b.yaml")
    assert np.linalg.norm(b["r0c1"].centre - b["r0c0"].centre) == pytest.approx(
        25 * np.linalg.norm(a["r0c1"].centre - a["r0c0"].centre), rel=1e-4
    )


# ---- a simulated 3x3 array ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def charuco_take(module_tmp: Callable[[str], Path]) -> Path:
    """120 board poses: enough for every camera's rotation to 0.01 degree (40 leave it at about 0.014)."""
    return record(module_tmp("calib"), "board", 120)


def detection_noise_floor(take: Path, report: dict) -> float:  # type: ignore[type-arg]
    """RMS distance of detected corners from their true projections (the simulation's noise floor)."""
    from rigctl.calib.detect import detect
    from rigctl.calib.inputs import load_views

    truth = load_calibration(take / "truth" / "calibration.yaml")
    poses = yaml.safe_load((take / "truth" / "board_poses.yaml").read_text())["poses"]
    views = load_views(take)
    views.frames = views.frames[::5]  # a sample is enough
    obs = detect(views, BoardSpec())
    corners = BoardSpec().corners_m()
    err = []
    for c, n in enumerate(views.names):
        for f, frame in enumerate(views.frames):
            m = (obs.cam == c) & (obs.frame == f)
            pose = poses[int(frame)]
            X = np.asarray(pose["origin"]) + corners[obs.pt[m]] @ np.asarray(pose["R"]).T
            err.append(truth[n].project(X) - obs.uv[m])
    e = np.concatenate(err)
    return float(np.sqrt((e**2).sum(1).mean()))


def raw_residuals_of_the_truth(take: Path, frames: list[str]) -> dict[str, dict[str, float]]:
    from rigctl.calib import metrics
    from rigctl.calib.detect import detect
    from rigctl.calib.inputs import load_views

    views = load_views(take)
    views.frames = [f for f in views.frames if f in set(frames)]
    obs = detect(views, BoardSpec())
    truth = load_calibration(take / "truth" / "calibration.yaml")
    res = metrics.rectification_residuals(truth, obs, views.names, list(range(len(views.frames))))
    keys = ("vertical_between_horizontal_neighbours", "horizontal_between_vertical_neighbours")
    return {k: dataclasses.asdict(getattr(res, k).raw) for k in keys}


def test_simulated_array_against_the_truth(charuco_take: Path, tmp_path: Path) -> None:
    out = tmp_path / "calibration.yaml"
    code, rep, err = calibrate(str(charuco_take), "--out", str(out), "--colmap", str(tmp_path / "colmap"))
    assert code == 0, err
    floor = detection_noise_floor(charuco_take, rep)
    # the bundle adjustment's RMS sits at the noise floor (slightly below: it absorbs a few degrees of freedom)
    assert abs(rep["rms_px"] - floor) <= 0.1 * floor, (rep["rms_px"], floor)
    truth = {n: c["truth"] for n, c in rep["cameras"].items()}
    assert max(t["centre_mm"] for t in truth.values()) < 1.0
    assert max(t["ray_deg"] for t in truth.values()) < 0.005
    # R alone trades off against the principal point (0.01 deg = 0.32 px here), so it needs more views than
    # the rays: 0.014 deg at 40 poses, 0.008 at 120, 0.006 at 160 (benchmarks/calibration_views.py)
    assert max(t["rotation_deg"] for t in truth.values()) < 0.01
    res = rep["rectification_residuals"]
    for key in ("vertical_between_horizontal_neighbours", "horizontal_between_vertical_neighbours"):
        net = res[key]["net"]
        assert net["n"] > 500 and net["rms"] <= 0.3 and net["p95"] <= 0.5, (key, net)
        # the raw figure includes the parallax of cameras mounted off the lattice (0.2 mm), which no
        # rectification can remove; it is reported, and larger
        assert res[key]["raw"]["rms"] >= net["rms"]
    assert res["disparity_ratio"]["relative"] == pytest.approx(1.0, abs=0.01)
    # the true calibration, rectified the same way, leaves the same raw figures on the same corners: they
    # measure how the rig was machined, not how well it was calibrated
    true_raw = raw_residuals_of_the_truth(charuco_take, res["held_out_frames"])
    for key, raw in true_raw.items():
        assert abs(res[key]["raw"]["rms"] - raw["rms"]) <= 0.1 * raw["rms"], (key, res[key]["raw"], raw)
    assert true_raw["horizontal_between_vertical_neighbours"]["rms"] > 0.3
    assert all(c["cross_validation_px"] < 0.3 for c in rep["cameras"].values())
    assert all(c["distortion_monotonic"] for c in rep["cameras"].values())
    # the file is the same schema as the simulator's truth, and the exports exist
    cal = load_calibration(out)
    assert cal.names == load_calibration(charuco_take / "truth" / "calibration.yaml").names
    assert (tmp_path / "calibration_coverage.png").exists() and (tmp_path / "calibration_residuals.png").exists()
    rigs = (tmp_path / "colmap" / "rigs.txt").read_text().splitlines()[-1].split()
    assert rigs[:4] == ["1", "9", "CAMERA", "1"]


def test_exports_round_trip(charuco_take: Path, tmp_path: Path) -> None:
    from rigctl.calib.export import quaternion, write_opencv_yaml

    cal = load_calibration(charuco_take / "truth" / "calibration.yaml")
    write_opencv_yaml(cal, tmp_path / "cv.yaml")
    fs = cv2.FileStorage(str(tmp_path / "cv.yaml"), cv2.FILE_STORAGE_READ)
    assert np.allclose(fs.getNode("r1c2_K").mat(), cal["r1c2"].K)
    assert np.allclose(fs.getNode("r1c2_t").mat().ravel(), cal["r1c2"].t)
    fs.release()
    for n in cal.names:  # the quaternion gives back the rotation
        w, x, y, z = quaternion(cal[n].R)
        R = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        assert np.allclose(R, cal[n].R, atol=1e-12)


# ---- takes that cannot constrain a calibration ------------------------------------------------------------------
def test_fronto_parallel_boards_are_diagnosed(tmp_path: Path) -> None:
    take = record(tmp_path, "flat", 8, "board_tilt_deg=0")
    code, _, err = calibrate(str(take), "--out", str(tmp_path / "c.yaml"))
    assert code == 3
    assert "nearly fronto-parallel" in err and "tilt the board 20-40 degrees" in err
    assert "calibration not written" in err and not (tmp_path / "c.yaml").exists()


def test_boards_that_never_reach_the_edges_are_diagnosed(tmp_path: Path) -> None:
    take = record(tmp_path, "far", 8, "board_distance_m=[4.5,5.0]", "board_tilt_deg=30")
    code, _, err = calibrate(str(take), "--out", str(tmp_path / "c.yaml"))
    assert code == 3
    assert "move the board towards the edges and corners of r2c0" in err


def test_too_few_views_are_diagnosed(tmp_path: Path) -> None:
    take = record(tmp_path, "few", 3)
    code, _, err = calibrate(str(take), "--out", str(tmp_path / "c.yaml"))
    assert code == 3 and "only 3 usable board views" in err and "record more board poses" in err


def test_a_camera_that_rarely_sees_the_board_is_named(tmp_path: Path) -> None:
    take = record(tmp_path, "t", 8)
    res = run_rigctl("take", "export", str(take), "--out", str(tmp_path / "sets"))
    assert res.returncode == 0, res.stderr
    sets = sorted(p for p in (tmp_path / "sets").iterdir() if p.is_dir())
    for frame in sets[2:]:
        (frame / "r2c2.png").unlink()  # r2c2 keeps 2 views
    code, _, err = calibrate(str(tmp_path / "sets"), "--out", str(tmp_path / "c.yaml"))
    assert code == 3 and "camera r2c2 sees the board in 2 views" in err and "hold the board in its view" in err


def test_bad_inputs_are_one_line(tmp_path: Path) -> None:
    code, _, err = calibrate(str(tmp_path / "nothing"), "--out", str(tmp_path / "c.yaml"))
    assert code == 3 and "no such take or folder" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = calibrate(str(empty), "--out", str(tmp_path / "c.yaml"))
    assert code == 3 and "no images found" in err
    # a refinement window larger than the images: cv2.error from cornerSubPix, a traceback (exit 1)
    code, _, err = calibrate(
        str(STEREO), "--chessboard", "9x6", "--subpix-window", "100000", "--out", str(tmp_path / "c.yaml")
    )
    assert code == 2 and "--subpix-window 100000: needs images at least 200005 px a side, got 640x480" in err, err
    assert len(err.splitlines()) == 1
    odd = tmp_path / "odd"
    odd.mkdir()
    shutil.copy(STEREO / "left01.jpg", odd / "cam01.jpg")
    code, _, err = calibrate(str(odd), "--out", str(tmp_path / "c.yaml"))
    assert code == 3 and "not grid positions" in err


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("squares_x: 100000", "squares_x: must be a whole number of squares 3 to 40, got 100000"),
        ("squares_y: 1", "squares_y: must be a whole number of squares 3 to 40, got 1"),
        ("square_m: .nan", "square_m: must be a length of 0.0001 to 1 m, got nan"),
        ("square_m: 1.0e+300", "square_m: must be a length of 0.0001 to 1 m, got 1e+300"),
        ("marker_m: 0.08", "marker_m: 0.08 must be smaller than square_m 0.075"),
    ],
    ids=["100000-squares", "1-square", "nan", "1e300", "marker-over-square"],
)
def test_a_board_description_out_of_what_rigctl_board_makes_is_one_line(tmp_path: Path, line: str, says: str) -> None:
    """calibrate --board read board.yaml's numbers as given: 100000 squares hung in OpenCV, 1e300 m squares
    were found in no view, the rest ended in a SystemError traceback from cv2.aruco.CharucoBoard (exit 1)."""
    take = record(tmp_path, "board", 4)
    board = BoardSpec().as_dict()
    key, value = line.split(": ")
    board[key] = yaml.safe_load(value)
    path = tmp_path / "board.yaml"
    path.write_text(yaml.safe_dump(board))
    res = run_rigctl("calibrate", str(take), "--board", str(path), "--out", str(tmp_path / "c.yaml"), timeout=60)
    assert res.returncode == 3 and len(res.stderr.splitlines()) == 1, res.stderr
    assert f"{path}: {says}" in res.stderr
