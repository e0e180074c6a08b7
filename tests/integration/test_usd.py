"""rigctl usd: the cameras of a simulated take's true calibration (mounting errors, focal spread, principal
point offsets) and of a rectified take, read back with usd-core and checked by projecting points through
the stage's own camera frusta against our projection."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom
from tests_support import run_rigctl

from rigctl.calibration_model import CameraModel, load_calibration
from rigctl.interop.usd import rectified_calibration


@pytest.fixture(scope="module")
def takes(module_tmp: Callable[[str], Path]) -> Path:
    out = module_tmp("usd")
    for name, extra in (("real", []), ("ideal", ["--sim", "ideal=true"])):
        res = run_rigctl("record", "--take", name, "--frames", "1", "--out", str(out), "--force",
                         "--sim", "motion=false", *extra)  # fmt: skip
        assert res.returncode == 0, res.stderr
    return out


def usd_pixels(prim: Usd.Prim, points: np.ndarray) -> np.ndarray:
    """Pixels of rig points (N x 3, our axes) through the USD camera's own frustum."""
    cam = UsdGeom.Camera(prim).GetCamera(Usd.TimeCode.Default())
    frustum = cam.frustum
    view, proj = frustum.ComputeViewMatrix(), frustum.ComputeProjectionMatrix()
    w, h = prim.GetAttribute("rigctl:imageSize").Get()
    out = []
    for p in points:
        stage_p = Gf.Vec3d(float(p[0]), -float(p[1]), -float(p[2]))  # rig axes -> the stage's (y up, z back)
        ndc = proj.Transform(view.Transform(stage_p))
        out.append(((ndc[0] + 1) / 2 * w - 0.5, (1 - ndc[1]) / 2 * h - 0.5))
    return np.array(out)


def pinhole(cam: CameraModel, points: np.ndarray) -> np.ndarray:
    pc = points @ cam.R.T + cam.t
    return np.column_stack(
        [cam.K[0, 0] * pc[:, 0] / pc[:, 2] + cam.K[0, 2], cam.K[1, 1] * pc[:, 1] / pc[:, 2] + cam.K[1, 2]]
    )


def points_in_view(cam: CameraModel, n: int = 40) -> np.ndarray:
    rng = np.random.default_rng(5)
    w, h = cam.image_size
    uv = np.column_stack([rng.uniform(0, w - 1, n), rng.uniform(0, h - 1, n)])
    z = rng.uniform(1.5, 4.0, n)
    ray = np.column_stack([(uv[:, 0] - cam.K[0, 2]) / cam.K[0, 0], (uv[:, 1] - cam.K[1, 2]) / cam.K[1, 1], np.ones(n)])
    return (ray * z[:, None] - cam.t) @ cam.R  # camera -> rig


def check_stage(path: Path, cams: dict[str, CameraModel]) -> float:
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    worst = 0.0
    for name, cam in cams.items():
        prim = stage.GetPrimAtPath(f"/rig/{name}")
        assert prim.IsA(UsdGeom.Camera), name
        pts = points_in_view(cam)
        worst = max(worst, float(np.abs(usd_pixels(prim, pts) - pinhole(cam, pts)).max()))
        assert UsdGeom.Camera(prim).GetFocalLengthAttr().Get() == pytest.approx(0.25)  # 25 mm in tenths of a metre
    return worst


def test_a_calibration_projects_through_the_stage_within_a_hundredth_of_a_pixel(takes: Path, tmp_path: Path) -> None:
    cal = takes / "real" / "truth" / "calibration.yaml"
    out = tmp_path / "rig.usda"
    res = run_rigctl("usd", str(cal), "--out", str(out), "--window")
    assert res.returncode == 0, res.stderr
    calib = load_calibration(cal)
    assert any(np.abs(calib[n].R - np.eye(3)).max() > 1e-3 for n in calib.names)  # really rotated cameras
    worst = check_stage(out, {n: calib[n] for n in calib.names})
    assert worst < 0.01, worst
    stage = Usd.Stage.Open(str(out))
    clip = UsdGeom.Camera(stage.GetPrimAtPath("/rig/r1c1")).GetClippingRangeAttr().Get()
    assert clip[0] == pytest.approx(1.948, abs=1e-3) and clip[1] == pytest.approx(2.948, abs=1e-3)  # the plan's
    window = np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/rig/window")).GetPointsAttr().Get())
    centres = np.array([calib[n].centre * [1, -1, -1] for n in calib.names])
    assert window.shape == (4, 3)
    assert np.ptp(window[:, 0]) == pytest.approx(np.ptp(centres[:, 0]), abs=0.01)  # spans the columns
    assert np.ptp(window[:, 1]) == pytest.approx(np.ptp(centres[:, 1]), abs=0.01)  # and the rows


def test_a_rectified_take_gives_its_common_camera(takes: Path, tmp_path: Path) -> None:
    out = tmp_path / "rectified.usd"
    res = run_rigctl("usd", str(takes / "ideal"), "--out", str(out), "--near", "1", "--far", "inf")
    assert res.returncode == 0, res.stderr
    calib = rectified_calibration(takes / "ideal")
    assert check_stage(out, {n: calib[n] for n in calib.names}) < 0.01
    stage = Usd.Stage.Open(str(out))
    r0c0 = UsdGeom.Xformable(stage.GetPrimAtPath("/rig/r0c0")).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    assert r0c0.ExtractTranslation()[0] < 0 < r0c0.ExtractTranslation()[1]  # top left seen from behind: y is up


def test_a_wrong_principal_point_would_show(takes: Path, tmp_path: Path) -> None:
    """The check can fail: a camera whose principal point is off by one pixel misses by about one pixel."""
    cal = takes / "real" / "truth" / "calibration.yaml"
    out = tmp_path / "rig.usda"
    assert run_rigctl("usd", str(cal), "--out", str(out)).returncode == 0
    calib = load_calibration(cal)
    cam = calib["r1c1"]
    K = cam.K.copy()
    K[0, 2] += 1.0
    moved = CameraModel(cam.name, K, cam.dist, cam.R, cam.t, cam.image_size)
    assert check_stage(out, {"r1c1": moved}) > 0.9


@pytest.mark.parametrize(
    ("out", "message"), [("rig.obj", "is .usda, .usd or .usdc"), ("exists.usda", "already exists")]
)
def test_bad_output_is_refused_in_one_line(takes: Path, tmp_path: Path, out: str, message: str) -> None:
    (tmp_path / "exists.usda").write_text("")
    res = run_rigctl("usd", str(takes / "real" / "truth" / "calibration.yaml"), "--out", str(tmp_path / out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and message in res.stderr, res.stderr


def test_a_clipping_range_beyond_what_a_float_holds_is_bounded_or_refused(takes: Path, tmp_path: Path) -> None:
    """Absurd but valid distances (a hostile-user review): a far beyond a million metres is that far, as the
    background at infinity is, not an infinite clipping range; a near below a millimetre is one line."""
    cal = takes / "real" / "truth" / "calibration.yaml"
    out = tmp_path / "far.usda"
    res = run_rigctl("usd", str(cal), "--out", str(out), "--near", "1", "--far", "1e300")
    assert res.returncode == 0, res.stderr
    stage = Usd.Stage.Open(str(out))  # held: a prim does not keep its stage
    clip = UsdGeom.Camera(stage.GetPrimAtPath("/rig/r1c1")).GetClippingRangeAttr().Get()
    assert tuple(clip) == (1.0, 1e6) and np.isfinite(np.array(clip)).all()
    res = run_rigctl("usd", str(cal), "--out", str(tmp_path / "near.usda"), "--near", "1e-300", "--far", "1e300")
    assert res.returncode == 2 and "--near 1e-300 m" in res.stderr and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and not (tmp_path / "near.usda").exists()
    bad = tmp_path / b"bad\xff.usda".decode("utf-8", "surrogateescape")
    res = run_rigctl("usd", str(cal), "--out", str(bad))
    assert res.returncode != 0 and "Traceback" not in res.stderr and "UTF-8" in res.stderr
