"""The renderer's compiled kernels (Numba, no Python objects inside): the per-frame preparation parallel
over rows, the per-view passes serial and free of the GIL, run on as many threads as the caller has.

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
  agreement of the two disparities) and the normalised sum, written as 8-bit RGBA; per block row a scalar
  fetch of the texel patches, then a branch-free pass per pixel that the compiler turns into SIMD. Serial
  and without the GIL over a stride of block rows: an eye pair runs each eye, target and shade, on its own thread (no
  hand-over between the passes, and no parallel region to wake: on two cores that was a third of a pair's
  time); a single view gives interleaved rows to every core.

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
# a block row's scratch of ``shade``: patch, seen, filter weights x and y, target disparity, valid
Rows = tuple[I64, F32, I64, I64, F32, I64]


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
def _tap(img: I64, y: int, x: int) -> int:
    """A texel, or zero outside the image (a constant border)."""
    h, w = img.shape
    return img[y, x] if 0 <= y < h and 0 <= x < w else 0


@njit(inline="always")
def _seen(dsrc: F32, y: int, x: int) -> np.float32:
    """A source's disparity, or none outside the image."""
    h, w = dsrc.shape
    return dsrc[y, x] if 0 <= y < h and 0 <= x < w else NONE


@njit(nogil=True, cache=True, error_model="numpy")
def _fetch(low: F32, by: int, first: int, m: int, img: I64, dsrc: F32, a: float, b: float, rows: Rows) -> None:
    """Pass 1 for one source and the ``m`` blocks of block row ``by`` from column ``first`` (scalar: the
    texture fetches): where the target's disparity puts each block in the source, its 3 x 3 texel patch (zero
    outside the image), the four nearest disparities (none outside) and the 7-bit filter weights."""
    patch, seen, qx_, qy_, dd, valid = rows
    h, w = img.shape
    y = 2 * by
    for i in range(m):
        d = low[by, first + i]
        if d <= NONE:
            valid[i], dd[i] = 0, 0.0
            seen[0, i] = seen[1, i] = seen[2, i] = seen[3, i] = 0.0
            continue
        valid[i], dd[i] = 1, d
        mx = np.float32(2 * (first + i)) - d * a
        my = np.float32(y) - d * b
        fx, fy = np.floor(mx), np.floor(my)
        ix, iy = int(fx), int(fy)
        qx = int((mx - fx) * np.float32(Q) + np.float32(0.5))
        qy = int((my - fy) * np.float32(Q) + np.float32(0.5))
        qx_[i], qy_[i] = qx, qy
        rx, ry = ix + (1 if 2 * qx >= Q else 0), iy + (1 if 2 * qy >= Q else 0)
        if ix >= 0 and ix + 2 < w and iy >= 0 and iy + 2 < h:
            for r in range(3):
                row = img[iy + r]
                patch[3 * r, i], patch[3 * r + 1, i], patch[3 * r + 2, i] = row[ix], row[ix + 1], row[ix + 2]
            s0, s1 = dsrc[ry], dsrc[ry + 1]
            seen[0, i], seen[1, i], seen[2, i], seen[3, i] = s0[rx], s0[rx + 1], s1[rx], s1[rx + 1]
        else:  # at the image's edge
            for r in range(3):
                for c in range(3):
                    patch[3 * r + c, i] = _tap(img, iy + r, ix + c)
            seen[0, i], seen[1, i] = _seen(dsrc, ry, rx), _seen(dsrc, ry, rx + 1)
            seen[2, i], seen[3, i] = _seen(dsrc, ry + 1, rx), _seen(dsrc, ry + 1, rx + 1)


@njit(nogil=True, cache=True, error_model="numpy")
def _add(
    taps: tuple[I64, I64, I64, I64], seen: F32, rows: Rows, k: tuple[float, float, float], sums: I64, m: int
) -> None:
    """Pass 2 for one pixel of each of the ``m`` blocks (no branches, contiguous rows: the compiler turns it
    into SIMD): its bilinear texel from its four taps of the patch, its weight (closeness x agreement of the
    source's disparity ``seen`` with the target's, floored) and both added to its sums: R | G << 32,
    B | A << 32 and the weight (integers: 2^20 for the nearest source's full weight; four sources stay below
    2^30 per lane)."""
    pa, pb, pc, pd = taps
    _, _, qx_, qy_, dd, valid = rows
    cl, cla, floor_k = k
    rg, ba, wt = sums[0], sums[1], sums[2]
    for i in range(m):
        qx, d = qx_[i], dd[i]
        t = _lerp(_lerp(pa[i], pb[i], qx), _lerp(pc[i], pd[i], qx), qy_[i])
        q = int(max(cl - abs(seen[i] - d) * cla, floor_k) + np.float32(0.5)) * valid[i]
        rg[i] += q * (t & 0xFF | (t & 0xFF0000) << 16)
        ba[i] += q * (t >> 32 & 0xFF | (t >> 48) << 32)
        wt[i] += q


@njit(inline="always")
def _rgba8(rg: int, ba: int, wt: int) -> np.uint32:
    """A pixel's sums over its weight as packed 8-bit RGBA; all zero (transparent black) without weight."""
    inv = np.float32(1.0) / np.float32(max(wt, 1))
    top, half = np.float32(255.0), np.float32(0.5)
    r = np.uint32(min(np.float32(rg & 0xFFFFFFFF) * inv + half, top))
    g = np.uint32(min(np.float32(rg >> 32) * inv + half, top))
    b = np.uint32(min(np.float32(ba & 0xFFFFFFFF) * inv + half, top))
    a = np.uint32(min(np.float32(ba >> 32) * inv + half, top))
    return r | g << 8 | b << 16 | a << 24


@njit(nogil=True, cache=True, error_model="numpy")
def _normalise(left: I64, right: I64, out: NDArray[np.uint32], x0: int, m: int) -> None:
    """Pass 3: the sums of the blocks' left and right pixels as 8-bit RGBA into ``out[x0]``, ``out[x0 + 1]``,
    ... (no branches: a pixel without weight has all sums zero)."""
    pairs = min(m, (out.shape[0] - x0) // 2)
    for i in range(pairs):
        out[x0 + 2 * i] = _rgba8(left[0, i], left[1, i], left[2, i])
        out[x0 + 2 * i + 1] = _rgba8(right[0, i], right[1, i], right[2, i])
    if pairs < m:  # an odd width: the last block has no right pixel
        out[x0 + 2 * pairs] = _rgba8(left[0, pairs], left[1, pairs], left[2, pairs])


@njit(nogil=True, cache=True, error_model="numpy")
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
    start: int = 0,
    step: int = 1,
) -> None:
    """Write the view's RGBA (packed: R in the low byte) into ``out`` (H x W) from the half-resolution
    target disparity (``low``, or ``ring`` -- the key's soft edge -- where ``low`` has none; ``low`` is
    completed in place) and the first ``n`` sources (texels as ``prepare_source`` makes them, H x W). Per
    pixel and source: one bilinear RGBA sample (7-bit weights; zero outside the image) and one nearest
    disparity sample where the target's disparity puts the point, weighted by closeness x agreement (floored
    at 1e-3 of the closeness); pixels with no target disparity are transparent black.

    The pixels of a 2x2 block share the target disparity (read at nearest) and so the bilinear weights; each
    pixel still takes its own four taps per source, as a pixel shader would. A block row is shaded in three
    passes over its span (fetch the patches, add each pixel's sample, normalise), so that the arithmetic runs
    in SIMD lanes. Serial and without the GIL: it shades the block rows ``start``, ``start + step``, ..., so
    that the caller can give one view's interleaved rows to several threads, or each eye its own thread."""
    h = out.shape[0]
    hl, wl = low.shape
    agree = np.float32(inv_agree)
    scale = np.float32(WEIGHT) / closeness[:n].max()
    rows = (
        np.zeros((9, wl), np.int64),  # the 3 x 3 texel patch of each block
        np.zeros((4, wl), np.float32),  # the source's disparity at each pixel's nearest tap
        np.zeros(wl, np.int64),  # horizontal filter weight (of 128)
        np.zeros(wl, np.int64),  # vertical filter weight
        np.zeros(wl, np.float32),  # the target's disparity
        np.zeros(wl, np.int64),  # 1 where the block has one
    )
    patch, seen = rows[0], rows[1]
    sums = np.zeros((4, 3, wl), np.int64)  # per pixel of a block (top left, top right, ...): RG, BA, weight
    for by in range(start, hl, step):
        first, last = wl, -1
        for bx in range(wl):
            if low[by, bx] <= NONE:
                low[by, bx] = ring[by, bx]
            if low[by, bx] > NONE:
                first, last = min(first, bx), bx
        y = 2 * by
        n_rows = min(2, h - y)
        if last < 0:
            out[y : y + n_rows, :] = 0
            continue
        m = last + 1 - first
        sums[:, :, :m] = 0
        for k in range(n):
            cl = closeness[k] * scale
            _fetch(low, by, first, m, texs[k], disps[k], du[k], dv[k], rows)
            for py in range(n_rows):
                for px in range(2):
                    j = 3 * py + px
                    taps = (patch[j], patch[j + 1], patch[j + 3], patch[j + 4])
                    _add(taps, seen[2 * py + px], rows, (cl, cl * agree, cl * np.float32(1e-3)), sums[2 * py + px], m)
        for py in range(n_rows):
            orow = out[y + py]
            orow[: 2 * first] = 0
            orow[2 * (last + 1) :] = 0
            _normalise(sums[2 * py], sums[2 * py + 1], orow, 2 * first, m)
