"""Reading a picture received from someone else: its header is checked against a pixel budget before a
byte is decoded (a 1 MB PNG can claim 32000 x 32000 pixels, 3 GB once decoded), and only a regular file of
bounded size is read. Decoding goes through memory (``cv2.imdecode``), so a path OpenCV cannot take (not
UTF-8) is no crash."""

from __future__ import annotations

import os
import struct
import zlib
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
    data = png_chunks(path, read_regular(path, MAX_FILE_BYTES, error, "image"), error)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.shape[:2] != (height, width):
        raise error(f"{path}: cannot decode the PNG image")
    return img


# what decoding needs; every other chunk (colour profile, text, gamma, time) is metadata OpenCV does not apply
DECODED_CHUNKS = (b"IHDR", b"PLTE", b"tRNS", b"IDAT", b"IEND")


def png_chunks(path: Path, data: bytes, error: type[RigctlError] = RigFileError) -> bytes:
    """``data`` (a PNG) with its chunks proven whole before libpng sees them, which otherwise prints its own
    ``libpng error: IDAT: CRC error`` or ``libpng warning: iCCP: ...`` lines on stderr beside ours: a chunk of a
    wrong checksum or cut short is refused naming its byte offset; the chunks decoding does not need are left
    out (their warnings with them; the pixels are the same)."""
    out, pos = [data[:8]], 8
    while pos < len(data):
        if pos + 12 > len(data):
            raise error(f"{path}: PNG cut short at byte {pos:,} (no whole chunk, no IEND)")
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, end = data[pos + 4 : pos + 8], pos + 12 + length
        if end > len(data):
            raise error(
                f"{path}: PNG cut short: chunk {kind.decode('latin-1')!r} at byte {pos:,} needs {length:,} bytes"
            )
        if kind in DECODED_CHUNKS:
            (crc,) = struct.unpack(">I", data[end - 4 : end])
            if zlib.crc32(data[pos + 4 : end - 4]) != crc:
                raise error(f"{path}: PNG chunk {kind.decode('latin-1')} at byte {pos:,} fails its checksum (damaged)")
            out.append(data[pos:end])
        pos = end
        if kind == b"IEND":
            return b"".join(out)
    raise error(f"{path}: PNG cut short at byte {pos:,} (no IEND chunk)")
