"""Middlebury PFM: 32-bit float images, rows stored bottom to top, scale sign giving endianness."""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import ParameterError, TakeError
from rigctl.publish import publish_bytes


def write_pfm(path: Path, image: NDArray[np.floating], durable: bool = True) -> None:
    """Write a single-channel (Pf) or RGB (PF) float image, little-endian, atomically."""
    img = np.asarray(image, dtype="<f4")
    if img.ndim == 2:
        header = b"Pf"
    elif img.ndim == 3 and img.shape[2] == 3:
        header = b"PF"
    else:
        raise ParameterError(f"{path}: PFM holds 1 or 3 channels, got shape {img.shape}")
    h, w = img.shape[:2]
    data = header + b"\n" + f"{w} {h}\n".encode() + b"-1.0\n" + np.ascontiguousarray(img[::-1]).tobytes()
    publish_bytes(path, data, durable)


HEADER_MAX = 256  # bytes: three short lines
PIXELS_MAX = 1 << 28  # per image (a 16K x 16K disparity map): beyond it, a header is lying


def read_pfm(path: Path) -> NDArray[np.float32]:
    """Read a PFM file; raises :class:`TakeError` naming the file and what is wrong. Only a regular file is
    read, and only after its header says how many bytes of pixels follow and the file holds exactly those: a
    device, a pipe or a junk file never costs more memory than the image it claims to be."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a FIFO would block an open without it
        with open(fd, "rb") as f:
            st = os.fstat(f.fileno())
            if not stat.S_ISREG(st.st_mode):
                raise TakeError(f"{path}: not a regular file")
            head = f.read(HEADER_MAX)
            parts = head.split(b"\n", 3)
            if len(parts) < 4 or parts[0] not in (b"Pf", b"PF"):
                raise TakeError(f"{path}: not a PFM file (byte 0: expected 'Pf' or 'PF' and a 3-line header)")
            w, h, scale = _header(path, parts[1], parts[2])
            channels = 3 if parts[0] == b"PF" else 1
            offset = len(parts[0]) + len(parts[1]) + len(parts[2]) + 3
            need = w * h * channels * 4
            if st.st_size - offset != need:
                raise TakeError(f"{path}: byte {offset}: expected {need} bytes of pixels, found {st.st_size - offset}")
            f.seek(offset)
            pixels = f.read(need)
    except OSError as exc:
        raise TakeError(f"{path}: cannot read: {exc.strerror}") from None
    if len(pixels) != need:
        raise TakeError(f"{path}: byte {offset}: expected {need} bytes of pixels, found {len(pixels)}")
    dtype = "<f4" if scale < 0 else ">f4"
    img = np.frombuffer(pixels, dtype=dtype).reshape((h, w, channels) if channels == 3 else (h, w))
    return np.ascontiguousarray(img[::-1]).astype(np.float32)


def _header(path: Path, size: bytes, scale_line: bytes) -> tuple[int, int, float]:
    """Width, height and scale from a PFM header's second and third lines."""
    try:
        w, h = (int(v) for v in size.split())
        scale = float(scale_line)
    except ValueError:
        raise TakeError(f"{path}: malformed PFM header (line 2: WIDTH HEIGHT, line 3: scale)") from None
    if w <= 0 or h <= 0 or w * h > PIXELS_MAX:
        raise TakeError(f"{path}: PFM header: size {w}x{h} (must be positive, at most {PIXELS_MAX} pixels)")
    if not math.isfinite(scale) or scale == 0:
        raise TakeError(f"{path}: PFM header: scale {scale_line.decode('ascii', 'replace')!r} (must be non-zero)")
    return w, h, scale
