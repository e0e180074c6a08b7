"""MPEG immersive-video (MIV) content out of a rectified take: the camera JSON of the common test conditions
(what MPEG's RVS and TMIV read), colour as planar YUV 4:2:0 at 10 bits and depth as normalised inverse depth
at 16 bits, one file each per camera, frames back to back.

**Axes.** Our rectified frame is OpenCV's (x right, y down, z forward, metres). MIV's (OMAF) is x forward,
y left, z up, metres, so a point (X, Y, Z) of ours is (Z, -X, -Y) there. Every camera of a rectified take
shares one orientation, which becomes MIV's world axes: ``Rotation`` is [0, 0, 0] for every camera and
``Position`` is the camera centre in those axes, relative to the mean of the centres. A camera point at
planar depth Z (along the optical axis, which is MIV's x) projects to u = -f y / x + cx in MIV and to
u = f X / Z + cx' in ours: the focal length is the same and MIV's principal point is ours + 0.5 px, because
MIV puts pixel centres at (j + 0.5, i + 0.5) and OpenCV at (j, i).

**Depth.** Z = f * spacing_x / disparity (rectification.geometry's definition). Level = round(65535 (1/Z - 1/far) /
(1/near - 1/far)), at least 1; level 0 marks a pixel without depth (+inf disparity: off the subject),
which RVS treats as a hole. ``Depth_range`` [near, far] spans every valid depth of every exported frame and camera: the
nearest codes as 65535 and the farthest as 1 (far is set one level beyond it), so no depth is clipped;
far >= 1000 m means infinity, as in RVS.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rigctl.disparity_layers import checked_disparity
from rigctl.errors import ParameterError, TakeError
from rigctl.interop import yuv
from rigctl.publish import publish_text, publishing_folder
from rigctl.take.framesets import check_frames

log = logging.getLogger(__name__)

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
COLOUR_BITS = 10
DEPTH_BITS = 16
JSON_NAME = "cameras.json"


def cv_to_omaf(p: F64) -> F64:
    """Points (..., 3) from our rectified axes (x right, y down, z forward) to MIV's (x forward, y left, z up)."""
    p = np.asarray(p, np.float64)
    return np.stack([p[..., 2], -p[..., 0], -p[..., 1]], axis=-1)


def omaf_to_cv(q: F64) -> F64:
    """Inverse of :func:`cv_to_omaf`."""
    q = np.asarray(q, np.float64)
    return np.stack([-q[..., 1], -q[..., 2], q[..., 0]], axis=-1)


def texture_name(camera: str, width: int, height: int) -> str:
    return f"{camera}_texture_{width}x{height}_yuv420p10le.yuv"


def depth_name(camera: str, width: int, height: int) -> str:
    return f"{camera}_depth_{width}x{height}_yuv420p16le.yuv"


def depth_levels(disparity: F32, focal_px: float, spacing: float, near: float, far: float) -> NDArray[np.uint16]:
    """Disparity (px for the horizontal spacing; +inf or <= 0: none) -> 16-bit normalised inverse depth."""
    d = disparity.astype(np.float64)
    valid = np.isfinite(d) & (d > 0)
    inv_z = np.where(valid, d, 0.0) / (focal_px * spacing)
    inv_far = 0.0 if far >= 1000.0 else 1.0 / far
    v = (inv_z - inv_far) / (1.0 / near - inv_far)
    top = (1 << DEPTH_BITS) - 1
    levels = np.clip(np.rint(v * top), 1, top)
    return np.where(valid, levels, 0).astype(np.uint16)


def levels_disparity(levels: NDArray[np.integer], focal_px: float, spacing: float, near: float, far: float) -> F32:
    """Inverse of :func:`depth_levels` (level 0: +inf, no depth); far >= 1000 m means infinity, as in RVS."""
    top = float((1 << DEPTH_BITS) - 1)
    v = levels.astype(np.float64) / top
    inv_far = 0.0 if far >= 1000.0 else 1.0 / far
    inv_z = inv_far + v * (1.0 / near - inv_far)
    return np.where(levels > 0, inv_z * focal_px * spacing, np.inf).astype(np.float32)


def camera_entry(
    name: str, position: F64, size: tuple[int, int], focal: float, principal_cv: tuple[float, float],
    depth_range: tuple[float, float],
) -> dict[str, Any]:  # fmt: skip
    """One camera of the JSON (``position`` already in MIV axes)."""
    return {
        "Name": name,
        "Position": [float(x) for x in position],
        "Rotation": [0.0, 0.0, 0.0],
        "Depthmap": 1,
        "Background": 0,
        "Depth_range": [float(depth_range[0]), float(depth_range[1])],
        "Resolution": [int(size[0]), int(size[1])],
        "Projection": "Perspective",
        "Focal": [float(focal), float(focal)],
        "Principle_point": [float(principal_cv[0]) + 0.5, float(principal_cv[1]) + 0.5],
        "BitDepthColor": COLOUR_BITS,
        "BitDepthDepth": DEPTH_BITS,
        "ColorSpace": "YUV420",
        "DepthColorSpace": "YUV420",
        "HasInvalidDepth": True,
    }


def _disparity(folder: Path, number: int, name: str, shape: tuple[int, int], take: Path) -> F32:
    from rigctl.disparity_layers import disparity_file, read_any_disparity

    path = disparity_file(folder / f"{number:06d}", name)  # the PFM or, without one, the depth EXR
    if not path.is_file():
        raise TakeError(f"{path}: no disparity for camera {name} of frame {number} (nor an EXR beside it)")
    return checked_disparity(path, read_any_disparity(path), shape, take)


def export_miv(take: Path, disparity_dir: Path, out: Path, frames: range | None = None) -> list[Path]:
    """Write ``take``'s frames (``frames``, default every complete frame set with a disparity) and their
    disparities as MIV content in the new folder ``out``; returns the files written."""
    from rigctl.depth.grid import TakeGrid

    if out.exists():
        raise ParameterError(f"{out}: already exists; MIV content goes into a new folder")
    if not (take / "take.yaml").is_file():
        raise ParameterError(f"{take}: not a take (no take.yaml)")
    if not disparity_dir.is_dir():
        raise ParameterError(f"{disparity_dir}: disparity folder does not exist")
    grid = TakeGrid(take)
    rect = grid.reader.manifest.rectification
    assert rect is not None  # TakeGrid refuses a take without it
    available = grid.frame_numbers()
    if frames is None:
        numbers = [n for n in available if (disparity_dir / f"{n:06d}").is_dir()]
        if not numbers:
            raise TakeError(f"{disparity_dir}: no disparity for any complete frame set of {take}")
    else:
        numbers = check_frames(frames, available, take)
    names = list(grid.names)
    width, height = int(rect.image_size[0]), int(rect.image_size[1])
    focal, spacing = float(rect.focal_px), float(rect.spacing_x_m)
    K = np.asarray(rect.K, np.float64)
    # the depth range: every valid depth of every frame exported
    inv = [np.float64(np.inf), np.float64(0.0)]
    for number in numbers:
        for name in names:
            d = _disparity(disparity_dir, number, name, (height, width), take)
            good = d[np.isfinite(d) & (d > 0)]
            if good.size:
                inv = [min(inv[0], good.min()), max(inv[1], good.max())]
    if not np.isfinite(inv[0]):
        raise TakeError(f"{disparity_dir}: no valid disparity in the frames exported: no depth to write")
    inv_near, inv_farthest = float(inv[1]) / (focal * spacing), float(inv[0]) / (focal * spacing)
    if inv_near <= inv_farthest * 1.0001:
        inv_near, inv_farthest = inv_near / 0.99, inv_farthest / 1.01  # one depth everywhere: a range around it
    # far one level beyond the farthest point, so that it codes as level 1, not 0 (no depth)
    inv_far = inv_farthest - (inv_near - inv_farthest) / ((1 << DEPTH_BITS) - 2)
    near, far = 1.0 / inv_near, (1.0 / inv_far if inv_far > 1e-3 else 1000.0)
    centres = np.array([rect.positions_m[n] for n in names], np.float64)
    positions = cv_to_omaf(centres - centres.mean(axis=0))
    cameras = [
        camera_entry(n, positions[i], (width, height), focal, (K[0, 2], K[1, 2]), (near, far))
        for i, n in enumerate(names)
    ]
    # built under a hidden partial name beside ``out`` and renamed once whole (rigctl.publish): a killed export
    # leaves no half content under ``out``, and the same command run again starts over
    with publishing_folder(out, "miv export", "already exists; MIV content goes into a new folder") as stage:
        publish_text(stage / JSON_NAME, json.dumps({"Version": "4.0", "cameras": cameras}, indent=2) + "\n")
        written = [JSON_NAME]
        handles = {}
        try:
            for cam in names:
                for kind in (texture_name(cam, width, height), depth_name(cam, width, height)):
                    handles[kind] = open(stage / kind, "wb")  # noqa: SIM115 - closed below, all together
                    written.append(kind)
            neutral = np.full(((height + 1) // 2, (width + 1) // 2), 1 << (DEPTH_BITS - 1), np.uint16)
            for number in numbers:
                g = grid.grid(number)
                for n in names:
                    planes = yuv.rgb_to_yuv420(g.images[n], COLOUR_BITS)
                    yuv.write_frame(handles[texture_name(n, width, height)], planes, COLOUR_BITS)
                    d = _disparity(disparity_dir, number, n, (height, width), take)
                    levels = depth_levels(d, focal, spacing, near, far)
                    yuv.write_frame(handles[depth_name(n, width, height)], [levels, neutral, neutral], DEPTH_BITS)
            for f in handles.values():  # on the device before the folder is renamed to its name
                f.flush()
                os.fsync(f.fileno())
        finally:
            for f in handles.values():
                f.close()
        written.append(_readme(stage, take, disparity_dir, numbers, names, width, height, (near, far)).name)
    return [out / name for name in written]


def _readme(
    out: Path, take: Path, disparity_dir: Path, numbers: list[int], names: list[str], w: int, h: int,
    depth_range: tuple[float, float],
) -> Path:  # fmt: skip
    first, last = numbers[0], numbers[-1]
    span = f"frame sets {first}-{last}" if len(numbers) > 1 else f"frame set {first}"
    lines = [
        f"MIV content written by rigctl from {take} ({span}, {len(numbers)} frame(s) per file, in that order) "
        f"and the disparity in {disparity_dir}.",
        f"{JSON_NAME}: the cameras (MIV/OMAF axes: x forward, y left, z up, metres; Rotation yaw, pitch, roll "
        f"in degrees), depth range {depth_range[0]:.4f}-{depth_range[1]:.4f} m.",
    ]
    for n in names:
        lines.append(f"{texture_name(n, w, h)}: camera {n}, colour, BT.709 limited range YCbCr 4:2:0, 10 bits LE.")
        lines.append(
            f"{depth_name(n, w, h)}: camera {n}, depth as normalised inverse depth in Depth_range, 16 bits LE "
            "(0: no depth), chroma neutral."
        )
    path = out / "README.txt"
    publish_text(path, "\n".join(lines) + "\n")
    return path
