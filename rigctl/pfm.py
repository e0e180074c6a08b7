"""Middlebury PFM: 32-bit float images, rows stored bottom to top, scale sign giving endianness."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import ParameterError, TakeError


def write_pfm(path: Path, image: NDArray[np.floating]) -> None:
    """Write a single-channel (Pf) or RGB (PF) float image, little-endian, atomically."""
    img = np.asarray(image, dtype="<f4")
    if img.ndim == 2:
        header = b"Pf"
    elif img.ndim == 3 and img.shape[2] == 3:
        header = b"PF"
    else:
        raise ParameterError(f"{path}: PFM holds 1 or 3 channels, got shape {img.shape}")
    h, w = img.shape[:2]
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(header + b"\n" + f"{w} {h}\n".encode() + b"-1.0\n")
        f.write(np.ascontiguousarray(img[::-1]).tobytes())
    os.replace(tmp, path)


def read_pfm(path: Path) -> NDArray[np.float32]:
    """Read a PFM file; raises :class:`TakeError` naming the file and what is wrong."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise TakeError(f"{path}: cannot read: {exc.strerror}") from None
    parts = data.split(b"\n", 3)
    if len(parts) < 4 or parts[0] not in (b"Pf", b"PF"):
        raise TakeError(f"{path}: not a PFM file (byte 0: expected 'Pf' or 'PF')")
    try:
        w, h = (int(v) for v in parts[1].split())
        scale = float(parts[2])
    except ValueError:
        raise TakeError(f"{path}: malformed PFM header") from None
    channels = 3 if parts[0] == b"PF" else 1
    offset = len(parts[0]) + len(parts[1]) + len(parts[2]) + 3
    need = w * h * channels * 4
    if len(parts[3]) != need:
        raise TakeError(f"{path}: byte {offset}: expected {need} bytes of pixels, found {len(parts[3])}")
    dtype = "<f4" if scale < 0 else ">f4"
    img = np.frombuffer(parts[3], dtype=dtype).reshape((h, w, channels) if channels == 3 else (h, w))
    return np.ascontiguousarray(img[::-1]).astype(np.float32)
