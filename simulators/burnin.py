"""A machine-readable frame id and camera id burnt into the top-left corner of every simulated frame.

Two rows of 32 blocks (luma 16 = 0, 235 = 1): camera index (8 bits), sequence number (24 bits), scene
frame (24 bits) and a checksum (8 bits). Tests and ``take check`` read it back to prove that nothing
was reordered or duplicated on the way to disk.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

BITS = 64


@dataclass(frozen=True)
class BurntId:
    camera_index: int
    sequence: int
    scene_frame: int


def block_px(width: int) -> int:
    return max(2, width // 320)


def _checksum(camera: int, seq: int, scene: int) -> int:
    return (camera * 31 + (seq & 0xFFFFFF) * 7 + (scene & 0xFFFFFF) * 13 + 0x5A) & 0xFF


def _bits(camera: int, seq: int, scene: int) -> NDArray[np.bool_]:
    word = (
        (camera & 0xFF) | ((seq & 0xFFFFFF) << 8) | ((scene & 0xFFFFFF) << 32) | (_checksum(camera, seq, scene) << 56)
    )
    return np.array([(word >> i) & 1 for i in range(BITS)], dtype=bool)


def burn(packed: NDArray[np.uint8], width: int, camera: int, seq: int, scene: int) -> None:
    """Write the id into packed 4:2:2 (UYVY) bytes in place."""
    b = block_px(width)
    bits = _bits(camera, seq, scene).reshape(2, 32)
    luma = np.where(bits, 235, 16).astype(np.uint8)
    block = np.repeat(np.repeat(luma, b, axis=0), b, axis=1)  # 2b x 32b pixels
    h, w = block.shape
    region = packed[:h, : 2 * w]
    region[:, 1::2] = block
    region[:, 0::2] = 128


def burn10(words: NDArray[np.uint16], width: int, camera: int, seq: int, scene: int) -> None:
    """Write the id into Y210 words (YUYV, 10 bits high) in place: luma 64 = 0, 940 = 1, chroma 512."""
    b = block_px(width)
    bits = _bits(camera, seq, scene).reshape(2, 32)
    luma = np.where(bits, 940 << 6, 64 << 6).astype(np.uint16)
    block = np.repeat(np.repeat(luma, b, axis=0), b, axis=1)
    h, w = block.shape
    region = words[:h, : 2 * w]
    region[:, 0::2] = block
    region[:, 1::2] = 512 << 6


def read(packed: NDArray[np.uint8], width: int) -> BurntId | None:
    """The id burnt into packed 4:2:2 bytes, or None if the checksum does not match."""
    b = block_px(width)
    ys = (np.arange(2) * b + b // 2)[:, None]
    xs = (np.arange(32) * b + b // 2)[None, :]
    luma = packed[ys, 2 * xs + 1]
    bits = (luma > 128).ravel()
    word = 0
    for i, bit in enumerate(bits):
        word |= int(bit) << i
    camera, seq, scene, check = word & 0xFF, (word >> 8) & 0xFFFFFF, (word >> 32) & 0xFFFFFF, word >> 56
    if check != _checksum(camera, seq, scene):
        return None
    return BurntId(camera, seq, scene)
