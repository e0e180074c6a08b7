"""Reading a picture received from someone else: its header is checked against a pixel budget before a
byte is decoded (a 1 MB PNG can claim 32000 x 32000 pixels, 3 GB once decoded), and only a regular file of
bounded size is read. Decoding goes through memory (``cv2.imdecode``), so a path OpenCV cannot take (not
UTF-8) is no crash."""

from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Any

from rigctl.errors import RigctlError, RigFileError
from rigctl.regular import open_regular, read_regular

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
MAX_SIDE = 16384
MIN_SIDE = 8
MAX_ASPECT = 64  # a 100000 x 1 picture is no camera's
MAX_PIXELS = 1 << 25  # 33.5 million pixels a picture (8K UHD is 33.2 million)
MAX_FILE_BYTES = 1 << 29


def png_size(path: Path, error: type[RigctlError] = RigFileError) -> tuple[int, int]:
    """(width, height) from a PNG's header, refused in one line unless within the budget."""
    fd, _ = open_regular(path, error, "image")
    try:
        head = os.pread(fd, 24, 0)
    finally:
        os.close(fd)
    if len(head) < 24 or head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise error(f"{path}: not a PNG image (no PNG signature and IHDR header)")
    width, height = struct.unpack(">II", head[16:24])
    if not (MIN_SIDE <= width <= MAX_SIDE and MIN_SIDE <= height <= MAX_SIDE) or width * height > MAX_PIXELS:
        raise error(
            f"{path}: {width}x{height} pixels is outside what rigctl decodes ({MIN_SIDE} to {MAX_SIDE} a side, "
            f"{MAX_PIXELS:,} pixels)"
        )
    if max(width, height) > MAX_ASPECT * min(width, height):
        raise error(f"{path}: {width}x{height} pixels: more than {MAX_ASPECT}:1 is no camera's picture")
    return width, height


def read_png(path: Path, error: type[RigctlError] = RigFileError) -> Any:
    """The PNG decoded as OpenCV reads it (``IMREAD_UNCHANGED``), its header checked first."""
    import cv2
    import numpy as np

    width, height = png_size(path, error)
    data = read_regular(path, MAX_FILE_BYTES, error, "image")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.shape[:2] != (height, width):
        raise error(f"{path}: cannot decode the PNG image")
    return img
