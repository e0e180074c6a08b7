"""The standard OpenEXR camera attributes of a rendered view and of a camera's depth output: ``worldToCamera``
and ``worldToNDC``, so NUKE (and anything else that reads them) can build the camera from the file.

As OpenEXR defines them, both are 4x4 matrices applied to row vectors (p' = p M). Camera space is
RenderMan's: x right, y up, z the viewing direction (left-handed). NDC is the image plane with (0, 0) at the
display window's top-left corner and (1, 1) at its bottom-right, y down. The world is the take's rectified
frame (x right, y down, z towards the scene, metres; a grid folder has none: its cameras at their offsets
times the spacing, r0c0 at the origin, in its spacing's unit), in which every camera of the grid and every
rendered view looks along +z. A pixel centre (j, i) in our (OpenCV) convention
is NDC ((j + 0.5) / W, (i + 0.5) / H); NDC's third coordinate is 1/Z, as in ``depth.Z``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def world_to_camera(centre: F64) -> F64:
    """Row-vector 4x4 from the rectified world to RenderMan camera space of a view at ``centre``."""
    s = np.diag([1.0, -1.0, 1.0])  # our y is down, RenderMan's up
    m = np.eye(4)
    m[:3, :3] = s
    m[:3, 3] = -s @ np.asarray(centre, np.float64)
    return m.T


def world_to_ndc(centre: F64, focal_px: float, principal: tuple[float, float], size: tuple[int, int]) -> F64:
    """Row-vector 4x4 from the rectified world to NDC of a view at ``centre`` (focal length and principal
    point in pixels, OpenCV's convention; ``size`` = (W, H))."""
    w, h = size
    cx, cy = principal
    proj = np.array(
        [
            [focal_px / w, 0.0, (cx + 0.5) / w, 0.0],
            [0.0, focal_px / h, (cy + 0.5) / h, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 0.0],
        ]
    )
    to_cam = np.eye(4)
    to_cam[:3, 3] = -np.asarray(centre, np.float64)
    return np.asarray((proj @ to_cam).T, np.float64)


def project_ndc(m: F64, point: F64, size: tuple[int, int]) -> tuple[float, float]:
    """A world point through a row-vector ``worldToNDC`` to pixels (OpenCV's convention)."""
    p = np.append(np.asarray(point, np.float64), 1.0) @ m
    return float(p[0] / p[3] * size[0] - 0.5), float(p[1] / p[3] * size[1] - 0.5)


def camera_attributes(
    centre: F64, focal_px: float, principal: tuple[float, float] | None, size: tuple[int, int]
) -> dict[str, object]:
    """``worldToCamera`` and ``worldToNDC`` as an EXR header carries them (float32 4x4) of a rectified camera or
    view at ``centre``; without a ``principal`` point (a grid folder) it is the picture's centre."""
    w, h = size
    if principal is None:
        principal = ((w - 1) / 2, (h - 1) / 2)
    return {
        "worldToCamera": np.ascontiguousarray(world_to_camera(centre), np.float32),
        "worldToNDC": np.ascontiguousarray(world_to_ndc(centre, focal_px, principal, size), np.float32),
    }
