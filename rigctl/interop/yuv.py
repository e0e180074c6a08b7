"""Raw planar YUV files as MPEG's tools read them, and the colour conversion between our pictures and them.

A ``.yuv`` file is frames back to back with no header: per frame the Y plane (W x H), then Cb and Cr
(ceil(W/2) x ceil(H/2) each for 4:2:0, none for 4:0:0); one byte per sample up to 8 bits, two bytes
little-endian from 9 to 16 bits. Colour is BT.709 YCbCr in limited ("video") range, scaled to the bit
depth as ITU-R BT.709 defines it (Y 16..235 and Cb/Cr 16..240 times 2^(bits - 8)), which is what MPEG's
immersive-video content uses. Chroma is sited at the centre of each 2x2 block (the mean of the four).
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import RigctlError

log = logging.getLogger(__name__)

U16 = NDArray[np.uint16]
F32 = NDArray[np.float32]
# BT.709 luma weights
KR, KB = 0.2126, 0.0722
KG = 1.0 - KR - KB


class YuvError(RigctlError):
    """A raw YUV file is missing, too short for the frame asked for, or holds values over its bit depth."""

    exit_code = 3


def _sample_bytes(bits: int) -> int:
    if not 1 <= bits <= 16:
        raise YuvError(f"bit depth must be 1 to 16, got {bits}")
    return 1 if bits <= 8 else 2


def frame_bytes(width: int, height: int, bits: int, chroma: bool = True) -> int:
    """Bytes of one 4:2:0 frame (``chroma`` False: 4:0:0, luma only)."""
    cw, ch = (width + 1) // 2, (height + 1) // 2
    return (width * height + (2 * cw * ch if chroma else 0)) * _sample_bytes(bits)


def frame_count(path: Path, width: int, height: int, bits: int, chroma: bool = True) -> int:
    """Whole frames in a file; a size that is not a whole number of frames is refused."""
    if width < 1 or height < 1:
        raise YuvError(f"{path}: picture size {width}x{height} is not positive")
    try:
        st = os.stat(path)
    except OSError as exc:
        raise YuvError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):  # /dev/zero has no size and never ends; a FIFO would block its read
        raise YuvError(f"{path}: not a regular file (a folder, device, pipe or socket): refused")
    size = st.st_size
    per = frame_bytes(width, height, bits, chroma)
    if size == 0:
        raise YuvError(f"{path}: empty: not one {width}x{height} {bits}-bit frame")
    if size % per:
        raise YuvError(f"{path}: {size} bytes is not a whole number of {width}x{height} {bits}-bit frames ({per})")
    return size // per


def read_frame(
    path: Path, width: int, height: int, bits: int, frame: int = 0, chroma: bool = True
) -> tuple[U16, U16 | None, U16 | None]:
    """Y, Cb, Cr planes of frame ``frame`` (Cb and Cr are None for 4:0:0). A file that is not a whole
    number of such frames is refused (the size or format given is not the file's)."""
    per = frame_bytes(width, height, bits, chroma)
    count = frame_count(path, width, height, bits, chroma)
    if frame < 0:
        raise YuvError(f"{path}: frame {frame}: frames are numbered from 0")
    if frame >= count:  # said here, whatever its size: a seek past an offset's range fails on its own
        raise YuvError(f"{path}: frame {frame} is past the end of the file ({count} frame(s) of {per} bytes)")
    dtype = np.dtype("<u2") if _sample_bytes(bits) == 2 else np.dtype(np.uint8)
    try:
        with open(path, "rb") as f:
            f.seek(frame * per)
            raw = f.read(per)
    except OSError as exc:
        raise YuvError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if len(raw) != per:
        raise YuvError(f"{path}: frame {frame} is past the end of the file ({len(raw)} of {per} bytes)")
    data = np.frombuffer(raw, dtype).astype(np.uint16)
    if int(data.max(initial=0)) >= 1 << bits:
        raise YuvError(f"{path}: frame {frame} holds values over {bits} bits")
    n = width * height
    y = data[:n].reshape(height, width)
    if not chroma:
        return y, None, None
    cw, ch = (width + 1) // 2, (height + 1) // 2
    cb = data[n : n + cw * ch].reshape(ch, cw)
    cr = data[n + cw * ch :].reshape(ch, cw)
    return y, cb, cr


def write_frame(f: object, planes: list[U16], bits: int) -> None:
    """Append one frame's planes (in order) to an open binary file."""
    dtype = np.dtype("<u2") if _sample_bytes(bits) == 2 else np.dtype(np.uint8)
    for p in planes:
        f.write(np.ascontiguousarray(p, dtype=dtype).tobytes())  # type: ignore[attr-defined]


def _ycbcr(rgb: F32, bits: int) -> NDArray[np.float64]:
    """(3, H, W) BT.709 limited-range YCbCr at ``bits``, unrounded, from R'G'B' float in [0, 1] (H, W, 3)."""
    r, g, b = (np.clip(rgb[..., i].astype(np.float64), 0.0, 1.0) for i in range(3))
    y = KR * r + KG * g + KB * b
    cb = (b - y) / (2 * (1 - KB))
    cr = (r - y) / (2 * (1 - KR))
    scale = float(1 << (bits - 8))
    return np.stack([(16 + 219 * y) * scale, (128 + 224 * cb) * scale, (128 + 224 * cr) * scale])


def _quantise(x: NDArray[np.float64], bits: int) -> U16:
    return np.clip(np.rint(x), 0, (1 << bits) - 1).astype(np.uint16)


def rgb_to_ycbcr(rgb: F32, bits: int) -> U16:
    """(3, H, W) BT.709 limited-range YCbCr at ``bits`` from non-linear R'G'B' float in [0, 1] (H, W, 3)."""
    return _quantise(_ycbcr(rgb, bits), bits)


def rgb_to_yuv420(rgb: F32, bits: int) -> list[U16]:
    """Y, Cb, Cr planes of 4:2:0 YCbCr at ``bits``: chroma the mean of each 2x2 block, rounded once (edges
    repeated when a size is odd)."""
    ycc = _ycbcr(rgb, bits)
    h, w = ycc.shape[1:]
    chroma = []
    for c in ycc[1:]:
        p = np.pad(c, ((0, h % 2), (0, w % 2)), mode="edge")
        chroma.append(_quantise((p[0::2, 0::2] + p[1::2, 0::2] + p[0::2, 1::2] + p[1::2, 1::2]) / 4, bits))
    return [_quantise(ycc[0], bits), *chroma]


def ycbcr_to_rgb(ycc: U16, bits: int) -> F32:
    """Inverse of :func:`rgb_to_ycbcr`: (H, W, 3) R'G'B' float in [0, 1] (clipped)."""
    scale = float(1 << (bits - 8))
    y = (ycc[0].astype(np.float64) / scale - 16) / 219
    cb = (ycc[1].astype(np.float64) / scale - 128) / 224
    cr = (ycc[2].astype(np.float64) / scale - 128) / 224
    r = y + 2 * (1 - KR) * cr
    b = y + 2 * (1 - KB) * cb
    g = (y - KR * r - KB * b) / KG
    return np.clip(np.stack([r, g, b], axis=-1), 0.0, 1.0).astype(np.float32)


def subsample_420(plane: U16) -> U16:
    """A full-size chroma plane as 4:2:0: the rounded mean of each 2x2 block (edges repeated when odd)."""
    h, w = plane.shape
    p = np.pad(plane.astype(np.uint32), ((0, h % 2), (0, w % 2)), mode="edge")
    s = p[0::2, 0::2] + p[1::2, 0::2] + p[0::2, 1::2] + p[1::2, 1::2]
    return ((s + 2) // 4).astype(np.uint16)
