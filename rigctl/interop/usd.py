"""The array's cameras as a USD stage (``pxr`` from ``usd-core``), for Unreal, Blender, Houdini and NUKE.

One ``UsdGeom.Camera`` per array camera under ``/rig``, from a calibration (each camera's own K, R, t) or
from a rectified take (the common camera: one K and orientation, each camera at its rectified centre).

**Units and axes.** The stage is in metres (``metersPerUnit`` 1) with Y up (``upAxis`` "Y"). Our rig frame
is OpenCV's (x right, y down, z towards the scene) and so is each camera's; USD's world here is x right, y up,
z towards the viewer behind the rig, and a USD camera looks down its -z with y up. Both changes are the
rotation F = diag(1, -1, -1), so a camera's local-to-world matrix is [F R^T F | F C] (C its centre).
Lens and filmback attributes are, as the USD schema defines them, in tenths of a scene unit: a 25 mm lens
is ``focalLength`` 0.25 on this metre stage. The focal length is the rig's lens (``f_mm``); the apertures
are the image size times the pixel pitch f / fx and f / fy (so fx != fy is kept); the principal point is
the aperture offsets, ``horizontalApertureOffset`` = (W/2 - 0.5 - cx) f / fx and
``verticalApertureOffset`` = (cy - H/2 + 0.5) f / fy (OpenCV puts pixel centres on integers, USD's
filmback spans the image's outer edges). ``clippingRange`` is the plan's near and far distances.
Lens distortion has no place in ``UsdGeom.Camera``: a calibration's cameras project as their pinhole part
(a rectified take has none). Each camera also carries ``rigctl:imageSize`` [W, H], to turn its normalised
device coordinates into pixels. Optionally ``/rig/window``: the light-field window, the rectangle the
camera centres span, as a mesh.
"""

from __future__ import annotations

import errno
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rigctl.calibration_model import ArrayCalibration, CameraModel
from rigctl.errors import OutputError, ParameterError
from rigctl.publish import check_creatable, publishing

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]
FLIP = np.diag([1.0, -1.0, -1.0])  # OpenCV axes <-> USD's (y up, z backwards), both ways
TENTHS_PER_MM = 1e-2  # tenths of a metre per millimetre


def camera_to_world(cam: CameraModel) -> F64:
    """4x4 local-to-world of the USD camera (column vectors), in the stage's axes."""
    m = np.eye(4)
    m[:3, :3] = FLIP @ cam.R.T @ FLIP
    m[:3, 3] = FLIP @ cam.centre
    return m


def lens(cam: CameraModel, focal_mm: float) -> dict[str, float]:
    """focalLength, apertures and their offsets (tenths of a metre) of ``cam`` with a ``focal_mm`` lens."""
    w, h = cam.image_size
    fx, fy, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
    f = focal_mm * TENTHS_PER_MM
    px, py = f / fx, f / fy
    return {
        "focalLength": f,
        "horizontalAperture": w * px,
        "verticalAperture": h * py,
        "horizontalApertureOffset": (w / 2 - 0.5 - cx) * px,
        "verticalApertureOffset": (cy - h / 2 + 0.5) * py,
    }


def write_stage(
    calib: ArrayCalibration, out: Path, focal_mm: float, clipping: tuple[float, float], window: bool = False,
    note: str = "",
) -> Path:  # fmt: skip
    """Write ``calib``'s cameras to the USD file ``out`` (``.usda`` text or ``.usd``/``.usdc``)."""
    from pxr import Gf, Sdf, Usd, UsdGeom

    near, far = clipping
    if not 0 < near < far:
        raise ParameterError(f"clipping range {near:g}-{far:g} m: needs 0 < near < far")
    if out.suffix not in (".usda", ".usd", ".usdc"):
        raise ParameterError(f"{out}: a USD stage is .usda, .usd or .usdc")
    if out.exists() or out.is_symlink():
        raise ParameterError(f"{out}: already exists")
    check_creatable(out)  # a place that cannot be written is one line before any work, not pxr's exception
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    root = UsdGeom.Xform.Define(stage, "/rig")
    stage.SetDefaultPrim(root.GetPrim())
    if note:
        stage.GetRootLayer().documentation = note
    for name in calib.names:
        cam = calib[name]
        prim = UsdGeom.Camera.Define(stage, f"/rig/{name}")
        prim.CreateProjectionAttr(UsdGeom.Tokens.perspective)
        values = lens(cam, focal_mm)
        prim.CreateFocalLengthAttr(values["focalLength"])
        prim.CreateHorizontalApertureAttr(values["horizontalAperture"])
        prim.CreateVerticalApertureAttr(values["verticalAperture"])
        prim.CreateHorizontalApertureOffsetAttr(values["horizontalApertureOffset"])
        prim.CreateVerticalApertureOffsetAttr(values["verticalApertureOffset"])
        prim.CreateClippingRangeAttr(Gf.Vec2f(near, far))
        prim.AddTransformOp().Set(Gf.Matrix4d(camera_to_world(cam).T.tolist()))  # Gf: row vectors
        size = prim.GetPrim().CreateAttribute("rigctl:imageSize", Sdf.ValueTypeNames.Int2)
        size.Set(Gf.Vec2i(*cam.image_size))
        if np.any(cam.dist != 0):
            prim.GetPrim().SetCustomDataByKey("rigctl:distortion", "not represented: this is the pinhole part")
    if window:
        corners = window_corners(calib)
        mesh = UsdGeom.Mesh.Define(stage, "/rig/window")
        mesh.CreatePointsAttr([Gf.Vec3f(*map(float, p)) for p in corners])
        mesh.CreateFaceVertexCountsAttr([4])
        mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    save_new(stage.GetRootLayer(), out)
    return out


def save_new(layer: Any, out: Path) -> None:
    """Publish ``layer`` as the new file ``out``, whole or not at all: exported under a hidden temporary name
    (with ``out``'s extension, which picks USD's file format) and linked to ``out`` only if nothing holds the
    name by then. A killed run leaves no half stage under ``out``; a failed write is one line."""
    from pxr import Tf

    with publishing(out, exists="already exists") as tmp:
        named = tmp.with_name(tmp.name + out.suffix)
        try:
            if not layer.Export(str(named)):
                raise OSError(errno.EIO, "USD could not write the stage")
        except Tf.ErrorException as exc:
            named.unlink(missing_ok=True)
            said = str(exc).strip().splitlines()[-1].rsplit(" : ", 1)[-1].strip(" '")  # pxr's own words, last
            raise OutputError(f"{out}: cannot write: {said}") from None
        os.rename(named, tmp)


def window_corners(calib: ArrayCalibration) -> F64:
    """The light-field window in the stage's axes: the rectangle the camera centres span, in the plane
    through their mean across the reference camera's viewing direction (counter-clockwise seen from the
    scene's side, so its normal faces the way the cameras look... from behind: the stage's -z)."""
    ref = calib[calib.reference]
    centres = np.array([calib[n].centre for n in calib.names])
    local = (centres - centres.mean(axis=0)) @ ref.R.T  # in the reference camera's axes
    x0, y0 = local[:, :2].min(axis=0)
    x1, y1 = local[:, :2].max(axis=0)
    quad = np.array([[x0, y0, 0.0], [x0, y1, 0.0], [x1, y1, 0.0], [x1, y0, 0.0]])
    return np.asarray((quad @ ref.R + centres.mean(axis=0)) @ FLIP.T, np.float64)


def rectified_calibration(take: Path) -> ArrayCalibration:
    """A rectified take's cameras: the common K and orientation (its rectified frame is the world), each
    at its rectified centre, no distortion."""
    from rigctl.take.manifest import read_manifest

    rect = read_manifest(take).rectification
    if rect is None:
        raise ParameterError(f"{take}: not a rectified take (no rectification section): give its calibration")
    K = np.asarray(rect.K, np.float64)
    size = (int(rect.image_size[0]), int(rect.image_size[1]))
    cams = {
        n: CameraModel(n, K, np.zeros(5), np.eye(3), -np.asarray(p, np.float64), size)
        for n, p in rect.positions_m.items()
    }
    ref = "r1c1" if "r1c1" in cams else sorted(cams)[0]
    return ArrayCalibration(str(take), cams, ref)
