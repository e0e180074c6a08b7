"""Pixel formats: packed 4:2:2 (UYVY, YUYV; 10-bit Y210 and v210, stored in a take at 20 bits a pixel, see
:mod:`rigctl.yuv10`) to and from RGB, BT.709 limited range as on HD/UHD SDI.

Float RGB keeps what the codes hold: super-whites (Y above 235 / 940, up to 254 / 1019) come out above 1.0
and sub-blacks below 0, so a scene-linear EXR keeps a camera's highlights. Only 8-bit outputs clip
(:func:`to_u8`, :func:`to_bgr8`, :func:`to_gray8`).

The simulator encodes with these functions and ``take export`` decodes with them, so colours round-trip
with the same matrix (OpenCV's own UYVY conversion, ``COLOR_YUV2BGR_UYVY``, uses BT.601, which would shift
every colour).

The frame path to 8 bits is direct: :func:`to_bgr8` turns packed 4:2:2 into BGR bytes in one
``cv2.transform`` pass (the BT.709 matrix with the limited-range scale folded in, six outputs per pixel
pair), the same numbers as :func:`uyvy_to_rgb` then :func:`to_u8` without the float image between them.
:func:`to_u8` is the project's one float-to-8-bit conversion: round half to even, saturated.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.errors import ParameterError
from rigctl.yuv10 import FLOOR_CODE, PEAK_CODE, is_ten_bit, pack, unpack

# BT.709: Y = 0.2126 R + 0.7152 G + 0.0722 B; limited range Y 16..235, Cb/Cr 16..240.
_KR, _KB = 0.2126, 0.0722
_KG = 1.0 - _KR - _KB
_RGB_TO_YCBCR = np.array(
    [
        [_KR, _KG, _KB],
        [-_KR / (2 * (1 - _KB)), -_KG / (2 * (1 - _KB)), 0.5],
        [0.5, -_KG / (2 * (1 - _KR)), -_KB / (2 * (1 - _KR))],
    ],
    dtype=np.float64,
)
_YCBCR_TO_RGB = np.linalg.inv(_RGB_TO_YCBCR)


def _packed_to_bgr_matrix(order: str) -> NDArray[np.float64]:
    """6 x 5: one packed pixel pair (4 code values and 1) to B, G, R of its two pixels, in 8-bit units."""
    bgr = _YCBCR_TO_RGB[::-1] * 255.0  # rows B, G, R; columns Y', Cb', Cr'
    y, cb, cr = bgr[:, 0] / 219.0, bgr[:, 1] / 224.0, bgr[:, 2] / 224.0
    offset = -(16.0 * y + 128.0 * cb + 128.0 * cr)
    zero = np.zeros(3)
    first: tuple[NDArray[np.floating], ...]
    second: tuple[NDArray[np.floating], ...]
    if order == "UYVY":  # U Y0 V Y1
        first, second = (cb, y, cr, zero), (cb, zero, cr, y)
    elif order == "YUYV":  # Y0 U Y1 V
        first, second = (y, cb, zero, cr), (zero, cb, y, cr)
    else:
        raise ParameterError(f"unknown packed 4:2:2 order {order!r}")
    return np.vstack([np.column_stack([*first, offset]), np.column_stack([*second, offset])])


_TO_BGR8 = {order: _packed_to_bgr_matrix(order) for order in ("UYVY", "YUYV")}
# full-range 8-bit grey from BT.709 luma: limited-range Y through a table; BGR through the luma weights
_Y_TO_GRAY8 = np.clip(np.rint((np.arange(256) - 16.0) * 255.0 / 219.0), 0, 255).astype(np.uint8)
_BGR_TO_GRAY = np.array([[_KB, _KG, _KR]])
_Y10_TO_GRAY8 = np.clip(np.rint((np.arange(1024) - 64.0) * 255.0 / 876.0), 0, 255).astype(np.uint8)


def video_range(pixel_format: str) -> tuple[float, float]:
    """The RGB values (nominal black 0, white 1) a format's codes can carry: 4:2:2 from its lowest valid code
    to its peak (8-bit 1-254, 10-bit 4-1019: sub-blacks and super-whites), full-range BGR3 and GREY [0, 1]."""
    if is_ten_bit(pixel_format):
        return (FLOOR_CODE - 64.0) / 876.0, (PEAK_CODE - 64.0) / 876.0
    if pixel_format in ("UYVY", "YUYV"):
        return (1.0 - 16.0) / 219.0, (254.0 - 16.0) / 219.0
    return 0.0, 1.0


def _pairs_in_code_values(rgb: NDArray[np.floating], bits: int, order: str) -> NDArray[np.float32]:
    """RGB (H x W x 3, W even) to H x W/2 x 4 float code values at ``bits`` in ``order`` (chroma averaged
    over each pixel pair), before rounding."""
    h, w, _ = rgb.shape
    if w % 2:
        raise ParameterError(f"packed 4:2:2 needs an even width, got {w}")
    k = float(1 << (bits - 8))
    scale = np.array([219.0 * k, 224.0 * k, 224.0 * k])[:, None]
    offset = np.array([16.0 * k, 128.0 * k, 128.0 * k])[:, None]
    m = np.hstack([_RGB_TO_YCBCR * scale, offset]).astype(np.float32)
    ycc = cv2.transform(np.ascontiguousarray(rgb, dtype=np.float32), m)  # Y, Cb, Cr in code values
    chroma = cv2.resize(np.ascontiguousarray(ycc[..., 1:]), (w // 2, h), interpolation=cv2.INTER_AREA)
    out = np.empty((h, w // 2, 4), dtype=np.float32)
    y0, y1 = ycc[:, 0::2, 0], ycc[:, 1::2, 0]
    if order == "UYVY":
        out[..., 0], out[..., 1], out[..., 2], out[..., 3] = chroma[..., 0], y0, chroma[..., 1], y1
    elif order == "YUYV":
        out[..., 0], out[..., 1], out[..., 2], out[..., 3] = y0, chroma[..., 0], y1, chroma[..., 1]
    else:
        raise ParameterError(f"unknown packed 4:2:2 order {order!r}")
    return out


def rgb_to_uyvy(rgb: NDArray[np.floating], order: str = "UYVY") -> NDArray[np.uint8]:
    """RGB (H x W x 3, W even; beyond [0, 1] up to the codes' range) to packed 4:2:2 bytes (H x 2W)."""
    h, w, _ = rgb.shape
    out = _pairs_in_code_values(rgb, 8, order)
    # convertScaleAbs rounds and saturates to 0..255 in one pass; 0 and 255 are SDI's timing codes
    codes = np.asarray(cv2.convertScaleAbs(out.reshape(h, 2 * w)), dtype=np.uint8)
    return np.clip(codes, 1, 254, out=codes)


def rgb_to_codes10(rgb: NDArray[np.floating]) -> NDArray[np.uint16]:
    """RGB (H x W x 3, W even; values beyond [0, 1] kept up to the codes' range) to 10-bit codes, H x 2W in
    UYVY order: computed in float and quantised once to 10 bits (never 8-bit codes shifted)."""
    h, w, _ = rgb.shape
    out = _pairs_in_code_values(rgb, 10, "UYVY")
    np.rint(out, out=out)
    np.clip(out, FLOOR_CODE, PEAK_CODE, out=out)
    return out.reshape(h, 2 * w).astype(np.uint16)


def _ycc_to_rgb(
    cb: NDArray[np.float32], y: NDArray[np.float32], cr: NDArray[np.float32], bits: int
) -> NDArray[np.float32]:
    """Codes (luma H x W, chroma H x W/2) to RGB float32, not clipped: super-whites above 1, sub-blacks below 0."""
    k = np.float32(1 << (bits - 8))
    h, w = y.shape
    ycc = np.empty((h, w, 3), dtype=np.float32)
    ycc[..., 0] = (y - 16.0 * k) / (219.0 * k)
    ycc[..., 1] = np.repeat((cb - 128.0 * k) / (224.0 * k), 2, axis=1)
    ycc[..., 2] = np.repeat((cr - 128.0 * k) / (224.0 * k), 2, axis=1)
    return ycc @ _YCBCR_TO_RGB.T.astype(np.float32)


def codes10_to_rgb(codes: NDArray[np.uint16]) -> NDArray[np.float32]:
    """10-bit codes (H x 2W, UYVY order) to RGB float32 (not clipped)."""
    h, n = codes.shape
    q = codes.reshape(h, n // 4, 4).astype(np.float32)
    y = np.empty((h, n // 2), dtype=np.float32)
    y[:, 0::2], y[:, 1::2] = q[..., 1], q[..., 3]
    return _ycc_to_rgb(q[..., 0], y, q[..., 2], 10)


def uyvy_to_rgb(packed: NDArray[np.uint8], order: str = "UYVY") -> NDArray[np.float32]:
    """Packed 4:2:2 bytes (H x 2W) to RGB float32 (chroma repeated over each pair); nominal black to white is
    [0, 1], super-whites and sub-blacks are kept beyond it."""
    h, w2 = packed.shape[:2]
    q = packed.reshape(h, w2 // 4, 4).astype(np.float32)
    if order == "UYVY":
        cb, y0, cr, y1 = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    elif order == "YUYV":
        y0, cb, y1, cr = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    else:
        raise ParameterError(f"unknown packed 4:2:2 order {order!r}")
    y = np.empty((h, w2 // 2), dtype=np.float32)
    y[:, 0::2], y[:, 1::2] = y0, y1
    return _ycc_to_rgb(cb, y, cr, 8)


def luma(packed: NDArray[np.uint8], order: str = "UYVY") -> NDArray[np.uint8]:
    """The Y plane of packed 4:2:2 bytes as an H x W view-free copy (fast path for matching)."""
    start = 1 if order == "UYVY" else 0
    return np.ascontiguousarray(packed[:, start::2])


def to_rgb(data: NDArray[np.uint8], pixel_format: str, width: int, height: int) -> NDArray[np.float32]:
    """A frame as a take stores it to RGB float32: [0, 1] from black to white, 4:2:2's super-whites above
    and sub-blacks below (full-range BGR3 and GREY stay within [0, 1])."""
    if is_ten_bit(pixel_format):
        return codes10_to_rgb(unpack(data, width, height))
    if pixel_format in ("UYVY", "YUYV"):
        return uyvy_to_rgb(data.reshape(height, width * 2), pixel_format)
    if pixel_format == "BGR3":
        return bgr8_to_rgb(data.reshape(height, width, 3))
    if pixel_format == "GREY":
        g = data.reshape(height, width).astype(np.float32) / 255.0
        return np.repeat(g[..., None], 3, axis=2)
    raise ParameterError(f"unsupported pixel format {pixel_format!r}")


def from_rgb(rgb: NDArray[np.floating], pixel_format: str) -> NDArray[np.uint8]:
    """RGB to the bytes of ``pixel_format`` as a take stores them (2-D array, rows of bytes); 4:2:2 keeps
    values beyond [0, 1] up to its codes' range, the 8-bit full-range formats clip at [0, 1]."""
    if is_ten_bit(pixel_format):
        return pack(rgb_to_codes10(rgb))
    if pixel_format in ("UYVY", "YUYV"):
        return rgb_to_uyvy(rgb, pixel_format)
    h, w, _ = rgb.shape
    if pixel_format == "BGR3":
        return to_u8(rgb).reshape(h, w * 3)
    if pixel_format == "GREY":
        return to_u8(np.asarray(rgb, dtype=np.float32) @ np.array([_KR, _KG, _KB], dtype=np.float32))
    raise ParameterError(f"unsupported pixel format {pixel_format!r}")


def to_u8(rgb: NDArray[np.floating]) -> NDArray[np.uint8]:
    """RGB in [0, 1] (H x W x 3) to 8-bit BGR, or grey (H x W) to 8-bit grey: x 255, rounded half to even,
    saturated. The one float-to-8-bit step of the project."""
    x = np.asarray(rgb)
    flipped = x[..., ::-1] if x.ndim == 3 else x
    scaled = np.multiply(flipped, 255.0, dtype=np.float32)
    np.rint(scaled, out=scaled)
    np.clip(scaled, 0.0, 255.0, out=scaled)
    return scaled.astype(np.uint8)


def to_bgr8(data: NDArray[np.uint8], pixel_format: str, width: int, height: int) -> NDArray[np.uint8]:
    """Any supported captured format to 8-bit BGR (H x W x 3) directly: BT.709 limited range for 4:2:2,
    clipped at nominal black and white (10-bit: through float RGB, rounded once)."""
    if is_ten_bit(pixel_format):
        return to_u8(to_rgb(data, pixel_format, width, height))
    if pixel_format in _TO_BGR8:
        pairs = data.reshape(height, width // 2, 4)
        return np.asarray(cv2.transform(pairs, _TO_BGR8[pixel_format]), np.uint8).reshape(height, width, 3)
    if pixel_format == "BGR3":
        return data.reshape(height, width, 3)
    if pixel_format == "GREY":
        return np.asarray(cv2.cvtColor(data.reshape(height, width), cv2.COLOR_GRAY2BGR), np.uint8)
    raise ParameterError(f"unsupported pixel format {pixel_format!r}")


def to_gray8(data: NDArray[np.uint8], pixel_format: str, width: int, height: int) -> NDArray[np.uint8]:
    """Any supported captured format to 8-bit full-range BT.709 luma (H x W)."""
    if is_ten_bit(pixel_format):
        return np.asarray(_Y10_TO_GRAY8[unpack(data, width, height)[:, 1::2]], np.uint8)
    if pixel_format in _TO_BGR8:
        return np.asarray(cv2.LUT(luma(data.reshape(height, width * 2), pixel_format), _Y_TO_GRAY8), np.uint8)
    if pixel_format == "BGR3":
        return np.asarray(cv2.transform(data.reshape(height, width, 3), _BGR_TO_GRAY), np.uint8).reshape(height, width)
    if pixel_format == "GREY":
        return data.reshape(height, width)
    raise ParameterError(f"unsupported pixel format {pixel_format!r}")


# every 8-bit value / 255 in float32 (numpy's own division), once per channel for cv2.LUT
_U8_UNIT = np.repeat((np.arange(256, dtype=np.float32) / np.float32(255.0))[None, :, None], 3, axis=2)


def bgr8_to_rgb(bgr: NDArray[np.uint8]) -> NDArray[np.float32]:
    """8-bit BGR to RGB float32 in [0, 1] (the exact inverse of :func:`to_u8` on 8-bit values). OpenCV swaps
    the channels and looks each value up in a table of v / 255 computed as :func:`bgr8_to_rgb_reference`
    divides, so the same floats, in one multi-threaded pass rather than numpy's two (issue 24: the depth
    makes a float picture about ten times a camera, 0.5 s a frame set at 1920x1080)."""
    if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8 or not bgr.size:
        return bgr8_to_rgb_reference(bgr)
    return np.asarray(cv2.LUT(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), _U8_UNIT), np.float32)


def bgr8_to_rgb_reference(bgr: NDArray[np.uint8]) -> NDArray[np.float32]:
    """:func:`bgr8_to_rgb` in numpy."""
    return bgr[..., ::-1].astype(np.float32) / np.float32(255.0)
