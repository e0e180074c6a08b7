"""10-bit 4:2:2: the layouts a device delivers and the one a take stores.

Devices deliver one of two layouts (the rig file's ``pixel_format``):

* ``Y210`` (V4L2_PIX_FMT_Y210): YUYV order, each sample in a 16-bit little-endian word with its 10
  significant bits in the high bits (the low 6 bits zero): 4 bytes a pixel.
* ``v210`` (QuickTime, SDI capture cards): Cb Y Cr Y ... three 10-bit samples in bits 0-9, 10-19 and 20-29
  of each 32-bit little-endian word (six pixels in four words), each line padded to a multiple of 128 bytes
  (48 pixels): 128 bits for six pixels, 21.3 bits a pixel.

A take stores either as **20 bits a pixel**: each pixel pair (Cb, Y0, Cr, Y1) in five bytes, the four 10-bit
samples one after the other, most significant bit first (the 4:2:2 10-bit "pgroup" of SMPTE ST 2110-20 /
RFC 4175), rows back to back with no padding. That is v210's information without its 2 spare bits a word
and its line padding: a 3840x2160 frame is 20,736,000 bytes (v210 22,118,400; Y210 33,177,600).

Samples in memory are *codes*: uint16, H x 2W, in UYVY order (Cb Y0 Cr Y1 ...), limited range (Y 64-940,
Cb/Cr 64-960, valid 4-1019). The conversions here are plain numpy; the recorder's hot path (device layout to
the take's, one pass per frame) and the unpacking every reader does are compiled (:mod:`rigctl.yuv10_kernels`,
imported on first use so that a command which never meets a 10-bit frame does not load Numba).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import ParameterError

TEN_BIT_FORMATS = ("Y210", "v210")
ESSENCE_BITS_PER_PIXEL = 20
PEAK_CODE, FLOOR_CODE = 1019, 4  # 10-bit codes 0-3 and 1020-1023 are SDI's timing references
U8 = NDArray[np.uint8]
U16 = NDArray[np.uint16]


def is_ten_bit(pixel_format: str) -> bool:
    return pixel_format in TEN_BIT_FORMATS


def v210_stride(width: int) -> int:
    """Bytes in one v210 line: 48 pixels (128 bytes) at a time."""
    return (width + 47) // 48 * 128


def device_frame_bytes(pixel_format: str, width: int, height: int) -> int:
    """Bytes of one frame as a device delivers ``pixel_format``."""
    if pixel_format == "Y210":
        return width * height * 4
    if pixel_format == "v210":
        return v210_stride(width) * height
    raise ParameterError(f"{pixel_format!r} is not a 10-bit 4:2:2 format ({', '.join(TEN_BIT_FORMATS)})")


def essence_frame_bytes(width: int, height: int) -> int:
    """Bytes of one 10-bit frame as a take stores it: 20 bits a pixel."""
    return width * height * ESSENCE_BITS_PER_PIXEL // 8


def check_width(width: int) -> None:
    if width % 2:
        raise ParameterError(f"10-bit 4:2:2 needs an even width, got {width}")


def pack(codes: U16) -> U8:
    """Codes (H x 2W, UYVY order) to the take's 20-bit packing (H x 5W/2 bytes)."""
    h, n = codes.shape
    q = codes.reshape(h, n // 4, 4).astype(np.uint64) & 0x3FF
    word = (q[..., 0] << 30) | (q[..., 1] << 20) | (q[..., 2] << 10) | q[..., 3]  # 40 bits a pixel pair
    out = np.empty((h, n // 4, 5), np.uint8)
    for i in range(5):
        out[..., i] = (word >> np.uint64(8 * (4 - i))) & 0xFF
    return out.reshape(h, -1)


def unpack(data: NDArray[np.uint8], width: int, height: int) -> U16:
    """The take's 20-bit packing to codes (H x 2W, UYVY order)."""
    from rigctl.yuv10_kernels import pgroups_to_codes

    check_width(width)
    src = np.ascontiguousarray(np.asarray(data, np.uint8).reshape(height, width * 5 // 2))
    out = np.empty((height, width * 2), np.uint16)
    pgroups_to_codes(src, out)
    return out


def to_device(codes: U16, pixel_format: str) -> U8:
    """Codes (UYVY order) to the bytes a device would deliver in ``pixel_format`` (H x line bytes)."""
    h, n = codes.shape
    w = n // 2
    if pixel_format == "Y210":
        yuyv = codes.reshape(h, w // 2, 4)[..., [1, 0, 3, 2]]
        return (yuyv.astype("<u2") << 6).reshape(h, -1).view(np.uint8)
    if pixel_format == "v210":
        stride = v210_stride(w)
        words = np.zeros((h, stride // 4), "<u4")
        m = -(-n // 3) * 3  # samples in whole words
        samples = np.zeros((h, m), "<u4")
        samples[:, :n] = codes & 0x3FF
        t = samples.reshape(h, m // 3, 3)
        words[:, : m // 3] = t[..., 0] | t[..., 1] << 10 | t[..., 2] << 20
        return words.view(np.uint8)
    raise ParameterError(f"{pixel_format!r} is not a 10-bit 4:2:2 format ({', '.join(TEN_BIT_FORMATS)})")


def from_device(data: NDArray[np.uint8], pixel_format: str, width: int, height: int) -> U16:
    """A device's frame in ``pixel_format`` to codes (H x 2W, UYVY order)."""
    raw = np.ascontiguousarray(
        np.asarray(data, np.uint8).reshape(-1)[: device_frame_bytes(pixel_format, width, height)]
    )
    if pixel_format == "Y210":
        yuyv = raw.view("<u2").reshape(height, width // 2, 4) >> 6
        return np.ascontiguousarray(yuyv[..., [1, 0, 3, 2]].reshape(height, width * 2)).astype(np.uint16)
    words = raw.view("<u4").reshape(height, -1)
    k = np.arange(width * 2)
    return ((words[:, k // 3] >> (10 * (k % 3)).astype("<u4")) & 0x3FF).astype(np.uint16)


def device_to_essence(src: memoryview, pixel_format: str, width: int, height: int, out: memoryview) -> memoryview:
    """The recorder's repacking: a device frame into ``out`` (at least :func:`essence_frame_bytes`) in the
    take's 20-bit packing, in one compiled pass; returns the filled part of ``out``."""
    from rigctl.yuv10_kernels import v210_to_pgroups, y210_to_pgroups

    size = essence_frame_bytes(width, height)
    dst = np.frombuffer(out, np.uint8, count=size).reshape(height, width * 5 // 2)
    if pixel_format == "Y210":
        y210_to_pgroups(np.frombuffer(src, "<u2", count=width * height * 2).reshape(height, width * 2), dst)
    elif pixel_format == "v210":
        words = v210_stride(width) // 4
        v210_to_pgroups(np.frombuffer(src, "<u4", count=words * height).reshape(height, words), dst)
    else:
        raise ParameterError(f"{pixel_format!r} is not a 10-bit 4:2:2 format ({', '.join(TEN_BIT_FORMATS)})")
    return out[:size]


class Repacker:
    """One camera writer's repacking of its device frames to the take's 20 bits a pixel, into one reused
    buffer. Made before capture starts: it runs the compiled pass once on a tiny frame, so the kernel is
    compiled (or loaded from Numba's cache) then, not on the take's first frame."""

    def __init__(self, pixel_format: str, width: int, height: int) -> None:
        self.pixel_format, self.width, self.height = pixel_format, width, height
        self.out = memoryview(bytearray(essence_frame_bytes(width, height)))
        tiny = memoryview(bytearray(device_frame_bytes(pixel_format, 2, 1)))
        device_to_essence(tiny, pixel_format, 2, 1, memoryview(bytearray(essence_frame_bytes(2, 1))))

    def __call__(self, data: memoryview) -> memoryview:
        """``data`` (a device frame) repacked; valid until the next call."""
        return device_to_essence(data, self.pixel_format, self.width, self.height, self.out)
