"""Rectification onto the array's common plane: the geometry (:mod:`.geometry`: :func:`common_plane` from a
calibration, the record a take's manifest keeps) and the remapping of a take's frames into a rectified take
(:mod:`.rectify`: :class:`Rectifier`, :func:`rectify_take`)."""

from rigctl.rectification.geometry import RectifiedGrid, calibration_hash, common_plane, rectification_record
from rigctl.rectification.rectify import (
    Rectifier,
    RectifyReport,
    check_rectification,
    frame_bgr,
    rectifier_for_take,
    rectify_take,
)

__all__ = [
    "RectifiedGrid",
    "Rectifier",
    "RectifyReport",
    "calibration_hash",
    "check_rectification",
    "common_plane",
    "frame_bgr",
    "rectification_record",
    "rectifier_for_take",
    "rectify_take",
]
