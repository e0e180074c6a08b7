"""Compiled passes over 10-bit 4:2:2 frames (layouts in :mod:`rigctl.yuv10`): the recorder repacks every
frame it stores, and every reader unpacks them, so these run once per frame and pixel. ``nogil``: each
camera's writer thread repacks its own frames beside the others."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _put(dst: np.ndarray, y: int, o: int, cb: int, y0: int, cr: int, y1: int) -> None:  # pragma: no cover
    dst[y, o] = cb >> 2
    dst[y, o + 1] = ((cb & 0x3) << 6) | (y0 >> 4)
    dst[y, o + 2] = ((y0 & 0xF) << 4) | (cr >> 6)
    dst[y, o + 3] = ((cr & 0x3F) << 2) | (y1 >> 8)
    dst[y, o + 4] = y1 & 0xFF


@njit(cache=True, nogil=True)
def y210_to_pgroups(src: np.ndarray, dst: np.ndarray) -> None:  # pragma: no cover  (compiled)
    """Y210 words (H x 2W: Y0 Cb Y1 Cr, 10 bits high) to five bytes a pixel pair (Cb Y0 Cr Y1, MSB first)."""
    h, n = src.shape
    for y in range(h):
        for p in range(n // 4):
            i = 4 * p
            _put(dst, y, 5 * p, src[y, i + 1] >> 6, src[y, i] >> 6, src[y, i + 3] >> 6, src[y, i + 2] >> 6)


@njit(cache=True, nogil=True)
def v210_to_pgroups(words: np.ndarray, dst: np.ndarray) -> None:  # pragma: no cover  (compiled)
    """v210 words (H x line words; sample k of a line in word k // 3 at bit 10 (k % 3)) to five bytes a pair:
    six pixels (four words, three pairs) at a time."""
    h = words.shape[0]
    pairs = dst.shape[1] // 5
    for y in range(h):
        for g in range((pairs + 2) // 3):
            w0, w1, w2, w3 = words[y, 4 * g], words[y, 4 * g + 1], words[y, 4 * g + 2], words[y, 4 * g + 3]
            p = 3 * g
            _put(dst, y, 5 * p, w0 & 0x3FF, (w0 >> 10) & 0x3FF, (w0 >> 20) & 0x3FF, w1 & 0x3FF)
            if p + 1 < pairs:
                _put(dst, y, 5 * p + 5, (w1 >> 10) & 0x3FF, (w1 >> 20) & 0x3FF, w2 & 0x3FF, (w2 >> 10) & 0x3FF)
            if p + 2 < pairs:
                _put(dst, y, 5 * p + 10, (w2 >> 20) & 0x3FF, w3 & 0x3FF, (w3 >> 10) & 0x3FF, (w3 >> 20) & 0x3FF)


@njit(cache=True, nogil=True, inline="always")
def _get(src: np.ndarray, y: int, o: int) -> tuple[int, int, int, int]:  # pragma: no cover
    """Cb, Y0, Cr, Y1 of the five bytes at ``src[y, o:o + 5]``."""
    b0, b1, b2, b3, b4 = np.uint16(src[y, o]), src[y, o + 1], src[y, o + 2], src[y, o + 3], src[y, o + 4]
    return (
        (b0 << 2) | (b1 >> 6),
        (np.uint16(b1 & 0x3F) << 4) | (b2 >> 4),
        (np.uint16(b2 & 0xF) << 6) | (b3 >> 2),
        (np.uint16(b3 & 0x3) << 8) | b4,
    )


@njit(cache=True, nogil=True)
def pgroups_to_codes(src: np.ndarray, dst: np.ndarray) -> None:  # pragma: no cover  (compiled)
    """Five bytes a pixel pair to codes (H x 2W, UYVY order)."""
    for y in range(src.shape[0]):
        for p in range(src.shape[1] // 5):
            dst[y, 4 * p], dst[y, 4 * p + 1], dst[y, 4 * p + 2], dst[y, 4 * p + 3] = _get(src, y, 5 * p)


@njit(cache=True, nogil=True)
def y210_to_v210(src: np.ndarray, words: np.ndarray) -> None:  # pragma: no cover  (compiled)
    """Y210 words (H x 2W) to v210 words (H x line words, padding zero): the simulator's v210 cameras."""
    h, n = src.shape
    for y in range(h):
        for i in range(words.shape[1]):
            words[y, i] = 0
        for k in range(n):
            # sample k of the UYVY order sits at Y210 word k ^ 1 (YUYV swaps each Y with its chroma)
            words[y, k // 3] |= np.uint32(src[y, k ^ 1] >> 6) << np.uint32(10 * (k % 3))


@njit(cache=True, nogil=True)
def pgroups_to_y210(src: np.ndarray, dst: np.ndarray) -> None:  # pragma: no cover  (compiled)
    """Five bytes a pixel pair to Y210 words (H x 2W: Y0 Cb Y1 Cr, 10 bits high): the simulator keeps its
    clean frames packed as a take stores them and unpacks one per delivered frame."""
    for y in range(src.shape[0]):
        for p in range(src.shape[1] // 5):
            cb, y0, cr, y1 = _get(src, y, 5 * p)
            dst[y, 4 * p], dst[y, 4 * p + 1], dst[y, 4 * p + 2], dst[y, 4 * p + 3] = y0 << 6, cb << 6, y1 << 6, cr << 6
