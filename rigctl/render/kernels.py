"""The renderer's compiled kernels (Numba, parallel over rows; no Python objects inside).

Three passes per view, each written as a GPU would run it:

- ``prepare_source`` -- once per frame and camera (the texture upload): RGB + key alpha to 8-bit RGBA
  texels (four 16-bit lanes of an int64), the
  disparity to float32 with ``NONE`` where there is none, and the range of its half-resolution samples;
- ``splat`` and ``close_and_fill`` -- the target's half-resolution disparity: every source's
  half-resolution samples forward-splatted with a depth test (a scatter with a max reduction), one-pixel
  cracks closed (OpenCV's 3x3 closing applied to holes only), disocclusions filled along rows then columns
  from the background side; OpenCV adds a ring of ``RING`` pixels for the key's soft edge. Serial and
  without the GIL: the two eyes of a pair run side by side on two threads;
- ``shade`` -- per full-resolution pixel, a fixed number of taps: for each of up to ``MAX_TAPS`` sources one
  bilinear RGBA sample (7-bit weights, all four channels per integer multiply) and one nearest disparity
  sample where the target's disparity puts the point, the weight (closeness in the array plane times
  agreement of the two disparities) and the normalised sum, written as 8-bit RGBA.

``cache=True`` keeps the machine code next to this file (or in Numba's user cache when that is read-only):
only the first call on a machine compiles (a few seconds, reported by ``rigctl bench render``).
"""

from __future__ import annotations

import logging
import os

# Numba's OpenMP threads spin between parallel regions by default; on two cores shared with other work (CI
# runs two CPU-bound processes beside the tests) a spinning thread holds the core the working one needs:
# the CPU time of a 1080p pair nearly doubled. Waiting threads sleep instead, unless the user chose.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

log = logging.getLogger(__name__)

NONE = np.float32(-1e6)  # "no disparity" inside the renderer (PFM's +inf would poison interpolation)
RING = 2  # half-resolution pixels of the key's soft edge kept around the subject
MAX_TAPS = 4  # sources per pixel: fixed, as in a pixel shader

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
I64 = NDArray[np.int64]


@njit(parallel=True, cache=True, fastmath=False)
def prepare_source(rgb: F32, alpha: F32, disparity: F32, tex: I64, disp: F32, half: F32, spans: I64) -> None:
    """Fill ``tex`` (H x W: 8-bit R, G, B and alpha 16 bits apart in one integer, so that one multiply
    weighs all four), ``disp`` (H x W, ``NONE`` where not finite),
    ``half`` (its even rows and columns: the splat's samples) and ``spans`` (per half-resolution row, the
    first and one past the last column holding a disparity; 0, 0 when none)."""
    h, w = alpha.shape
    hl, wl = half.shape
    top = np.float32(255.0)
    for y in prange(h):
        for x in range(w):
            v = int(min(max(alpha[y, x] * top + np.float32(0.5), 0.0), top))
            for c in range(2, -1, -1):
                v = v << 16 | int(min(max(rgb[y, x, c] * top + np.float32(0.5), 0.0), top))
            tex[y, x] = v
            d = disparity[y, x]
            disp[y, x] = d if np.isfinite(d) else NONE
    for j in prange(hl):
        first, last = wl, -1
        for i in range(wl):
            d = disp[2 * j, 2 * i]
            half[j, i] = d
            if d > NONE:
                first, last = min(first, i), i
        spans[j, 0], spans[j, 1] = (first, last + 1) if last >= 0 else (0, 0)


@njit(cache=True, nogil=True, fastmath=False)
def splat(halves: tuple[F32, ...], spans: tuple[I64, ...], n: int, du: F32, dv: F32, low: F32) -> None:
    """Forward-splat the half-resolution disparities of the first ``n`` sources (offsets du, dv from the
    target, in horizontal spacings) into ``low`` (hl x wl) with a depth test: the largest disparity (the
    nearest surface) wins. Serial (a scatter with a max has no race-free parallel form without a buffer per
    thread); an eye pair runs its two splats side by side instead."""
    hl, wl = low.shape
    low[:, :] = NONE
    for k in range(n):
        src, span = halves[k], spans[k]
        a, b = du[k], dv[k]
        for j in range(hl):
            fy = np.float32(2 * j)
            for i in range(span[j, 0], span[j, 1]):
                d = src[j, i]
                if d > NONE:
                    xt = int(np.rint((np.float32(2 * i) + d * a) * np.float32(0.5)))
                    yt = int(np.rint((fy + d * b) * np.float32(0.5)))
                    if 0 <= xt < wl and 0 <= yt < hl and d > low[yt, xt]:
                        low[yt, xt] = d


@njit(cache=True, nogil=True, fastmath=False)
def close_and_fill(low: F32, closed: F32, max_gap: int, last: NDArray[np.int64]) -> None:
    """In one pass down the rows of the splatted half-resolution disparity ``low``: holes take the 3x3
    closing ``closed`` where it has a value (one-pixel cracks), then runs of holes between two valid pixels
    at most ``max_gap`` apart take the smaller (farther) disparity of the two -- along the row, then, with
    ``last`` (one entry per column) remembering each column's last valid row, along the columns."""
    hl, wl = low.shape
    last[:] = -1
    for y in range(hl):
        row = low[y]
        for x in range(wl):
            if row[x] <= NONE and closed[y, x] > NONE:
                row[x] = closed[y, x]
        prev = -1
        for x in range(wl):
            if row[x] > NONE:
                if 0 <= prev < x - 1 and x - prev <= max_gap:
                    fill = min(row[prev], row[x])
                    for xx in range(prev + 1, x):
                        row[xx] = fill
                prev = x
        for x in range(wl):
            if row[x] > NONE:
                top = last[x]
                if 0 <= top < y - 1 and y - top <= max_gap:
                    fill = min(low[top, x], row[x])
                    for yy in range(top + 1, y):
                        low[yy, x] = fill
                last[x] = y


# A texel: 8-bit R, G, B, A in the low bytes of four 16-bit lanes of an int64. Filter weights are 7-bit
# (positions to 1/128 pixel, finer than cv2.remap's 1/32), so a weighted sum of two texels stays below
# 255 * 128 < 2^15 in every lane: no carry into the next lane, never the sign bit.
WEIGHT = 1 << 20  # the nearest source's full weight in the integer sums
LANES = 0x00FF00FF00FF00FF
HALF = 0x0040004000400040  # rounding: half of the weights' 128 in every lane
Q = 128


@njit(inline="always")
def _lerp(a: int, b: int, q: int) -> int:
    """Texels ``a`` and ``b`` mixed with 7-bit weight ``q`` (of 128) on ``b``, all four channels at once."""
    return ((Q - q) * a + q * b + HALF) >> 7 & LANES


@njit(inline="always")
def _row(img: I64, y: int, x: int, qx: int) -> tuple[int, int]:
    """The horizontal half of the bilinear filter for the two pixels of a block on row ``y``: taps x, x + 1
    (left pixel) and x + 1, x + 2 (right pixel)."""
    p1 = img[y, x + 1]
    return _lerp(img[y, x], p1, qx), _lerp(p1, img[y, x + 2], qx)


@njit(inline="always")
def _tap(img: I64, y: int, x: int) -> int:
    """A texel, or zero outside the image (a constant border)."""
    h, w = img.shape
    return img[y, x] if 0 <= y < h and 0 <= x < w else 0


@njit(inline="always")
def _add(cell: I64, wk: float, t: int) -> None:
    """Add texel ``t`` with weight ``wk`` (at most ``WEIGHT``) to a pixel's sums: R and G 32 bits apart in
    ``cell[0]``, B and A in ``cell[1]``, the weight in ``cell[2]`` (integers: no float conversion per
    channel; four sources sum to under 2^30 per lane)."""
    q = int(wk + np.float32(0.5))
    cell[0] += q * (t & 0xFF | (t & 0xFF0000) << 16)
    cell[1] += q * (t >> 32 & 0xFF | (t >> 48) << 32)
    cell[2] += q


@njit(parallel=True, cache=True, fastmath=False)
def shade(
    low: F32,
    ring: F32,
    texs: tuple[I64, ...],
    disps: tuple[F32, ...],
    n: int,
    du: F32,
    dv: F32,
    closeness: F32,
    inv_agree: float,
    out: NDArray[np.uint32],
) -> None:
    """Write the view's RGBA (packed: R in the low byte) into ``out`` (H x W) from the half-resolution
    target disparity (``low``, or ``ring`` -- the key's soft edge -- where ``low`` has none; ``low`` is
    completed in place) and the first ``n`` sources (texels as ``prepare_source`` makes them, H x W). Per
    pixel and source: one bilinear RGBA sample (7-bit weights; zero outside the image) and one nearest
    disparity sample where the target's
    disparity puts the point, weighted by closeness x agreement (floored at 1e-3 of the closeness); pixels
    with no target disparity are transparent black.

    One iteration is a 2x2 block of pixels, which share the target disparity (read at nearest) and so the
    bilinear weights; each pixel still takes its own four taps per source, as a pixel shader would."""
    h, w = out.shape
    hl, wl = low.shape
    one = np.float32(1.0)
    floor_w = np.float32(1e-3)
    agree = np.float32(inv_agree)
    scale = np.float32(WEIGHT) / closeness[:n].max()
    for by in prange(hl):
        first, last = wl, -1
        for bx in range(wl):
            if low[by, bx] <= NONE:
                low[by, bx] = ring[by, bx]
            if low[by, bx] > NONE:
                first, last = min(first, bx), bx
        y = 2 * by
        rows = min(2, h - y)
        if last < 0:
            out[y : y + rows, :] = 0
            continue
        # per pixel: weighted R | G << 32, B | A << 32 and the weight, summed over the sources
        acc = np.zeros((2, 2 * (last + 1 - first), 3), np.int64)
        for k in range(n):
            img, dsrc = texs[k], disps[k]
            a, b, cl = du[k], dv[k], closeness[k] * scale
            cla = cl * agree
            for bx in range(first, last + 1):
                d = low[by, bx]
                if d <= NONE:
                    continue
                mx = np.float32(2 * bx) - d * a
                my = np.float32(y) - d * b
                fx, fy = np.floor(mx), np.floor(my)
                ix, iy = int(fx), int(fy)
                qx = int((mx - fx) * np.float32(Q) + np.float32(0.5))
                qy = int((my - fy) * np.float32(Q) + np.float32(0.5))
                rx, ry = (1 if 2 * qx >= Q else 0), (1 if 2 * qy >= Q else 0)
                ax = 2 * bx
                c = ax - 2 * first
                floor_k = cl * floor_w
                if ix >= 0 and ix + 2 < w and iy >= 0 and iy + 2 < h and ax + 1 < w and y + 1 < h:
                    # the block's four pixels take their taps from one 3 x 3 patch (3 x 2 when qy is 0)
                    t00, t01 = _row(img, iy, ix, qx)
                    t10, t11 = _row(img, iy + 1, ix, qx)
                    if qy:
                        t20, t21 = _row(img, iy + 2, ix, qx)
                        t00, t01 = _lerp(t00, t10, qy), _lerp(t01, t11, qy)
                        t10, t11 = _lerp(t10, t20, qy), _lerp(t11, t21, qy)
                    s0, s1 = dsrc[iy + ry], dsrc[iy + 1 + ry]
                    _add(acc[0, c], max(cl - abs(s0[ix + rx] - d) * cla, floor_k), t00)
                    _add(acc[0, c + 1], max(cl - abs(s0[ix + 1 + rx] - d) * cla, floor_k), t01)
                    _add(acc[1, c], max(cl - abs(s1[ix + rx] - d) * cla, floor_k), t10)
                    _add(acc[1, c + 1], max(cl - abs(s1[ix + 1 + rx] - d) * cla, floor_k), t11)
                    continue
                # at the image's edge: the same filter, taps outside reading zero (a constant border)
                for py in range(rows):
                    for px in range(min(2, w - ax)):
                        x0, y0 = ix + px, iy + py
                        top = _lerp(_tap(img, y0, x0), _tap(img, y0, x0 + 1), qx)
                        t = _lerp(top, _lerp(_tap(img, y0 + 1, x0), _tap(img, y0 + 1, x0 + 1), qx), qy)
                        ny, nx = y0 + ry, x0 + rx
                        seen = dsrc[ny, nx] if 0 <= nx < w and 0 <= ny < h else NONE
                        _add(acc[py, c + px], max(cl - abs(seen - d) * cla, floor_k), t)
        for py in range(rows):
            orow = out[y + py]
            orow[: 2 * first] = 0
            orow[2 * (last + 1) :] = 0
            for x in range(2 * first, min(w, 2 * (last + 1))):
                cell = acc[py, x - 2 * first]
                if cell[2] > 0:
                    inv = one / np.float32(cell[2])
                    v = np.uint32(0)
                    for ch in range(4):
                        total = cell[ch >> 1] >> (32 * (ch & 1)) & 0xFFFFFFFF
                        v |= np.uint32(min(np.float32(total) * inv + np.float32(0.5), np.float32(255.0))) << (8 * ch)
                    orow[x] = v
                else:
                    orow[x] = 0
