"""Truth for novel views: the scene rendered by a virtual camera anywhere in the array plane, with the
rectified geometry's intrinsics and orientation, through the same pixel format as the real cameras."""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import NDArray
from rigctl.simulators.array import SimArray, _rays_for
from rigctl.simulators.raycast import render

from rigctl.calibration_model import CameraModel
from rigctl.errors import ParameterError
from rigctl.pixfmt import from_rgb, to_rgb, video_range
from rigctl.rig import CAMERA_NAME

log = logging.getLogger(__name__)


def virtual_centre(array: SimArray, col: float, row: float) -> NDArray[np.float64]:
    """Rig coordinates of grid position (col, row), affine in the cameras' true centres."""
    names = array.names
    rc = []
    for n in names:
        m = CAMERA_NAME.match(n)
        assert m is not None
        rc.append((1.0, float(m[2]), float(m[1])))
    centres = np.array([array.calibration[n].centre for n in names])
    coef, *_ = np.linalg.lstsq(np.array(rc), centres, rcond=None)
    return np.asarray(np.array([1.0, col, row]) @ coef, dtype=np.float64)


def virtual_view(array: SimArray, state: int, col: float, row: float) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """RGB in [0, 1] (after the rig's pixel format, as a camera there would have captured it) and the
    subject mask of a virtual rectified camera at grid position (col, row)."""
    if not (np.isfinite(col) and np.isfinite(row)):
        raise ParameterError(f"virtual camera at {col},{row}: position must be finite")
    grid = array.rectified
    c = virtual_centre(array, col, row)
    cam = CameraModel(f"c{col:g}r{row:g}", grid.K.copy(), np.zeros(5), grid.R.copy(), -grid.R @ c, grid.image_size)
    xs, ys = np.meshgrid(
        np.arange(grid.image_size[0], dtype=np.float32), np.arange(grid.image_size[1], dtype=np.float32)
    )
    res = render(array.scene(state), _rays_for(cam, (xs, ys)))
    fmt = array.format
    lo, hi = video_range(fmt.pixel_format)
    rgb = to_rgb(from_rgb(np.clip(res.rgb, lo, hi), fmt.pixel_format), fmt.pixel_format, fmt.width, fmt.height)
    return rgb, res.subject
