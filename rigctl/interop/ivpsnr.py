"""IV-PSNR, MPEG's quality metric for immersive video (Dziembowski, Mieloch, Stankowski, Grzelka, IEEE TCSVT
32(11), 2022), written from the paper's description and the behaviour of the authors' reference software
(which the tests run on the authors' published pictures).

Two pictures in YCbCr at one bit depth, every component at full resolution (4:2:0 chroma is first brought to
full size by repeating each sample over its 2x2 block, as the reference does):

1. **Global colour offset.** Per component, the mean of (test - reference), rounded half to even and
   clipped to the *unnoticeable difference* (``coef`` times the peak value, rounded: 3 levels at 8 bits for
   the default 0.01): a uniform shift of colour that a viewer does not notice is forgiven.
2. **Corresponding pixel shift.** For each pixel of one picture, offset by the global shift, the best match
   in a (2 s + 1)^2 window of the other picture (s = 2 by default; outside the picture the edge pixel is
   repeated), best by the component-weighted squared error 4:1:1 (Y:Cb:Cr); the first best in raster order
   when several tie. The squared differences to that match are summed per component.
3. Per component PSNR = 10 log10(N peak^2 / SSD) (an SSD of 0 counts as 1, so identical pictures give a
   finite figure), averaged with the weights 4:1:1, in both directions (test against reference and reference
   against test, the offset negated); IV-PSNR is the lower of the two.

With a mask, only pixels whose mask is non-zero are compared, each weighted by its mask value, and a window
candidate whose mask is zero is never a match; N is the number of non-zero mask pixels times the mask's
peak. The mean offset is the mask-weighted mean.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

log = logging.getLogger(__name__)

U16 = NDArray[np.uint16]
WEIGHTS = (4, 1, 1)
SEARCH_RANGE = 2
UNNOTICEABLE = 0.01


@dataclass(frozen=True)
class IvPsnr:
    """IV-PSNR of a test picture against a reference, with its parts."""

    ivpsnr_db: float
    psnr_db: tuple[float, float, float]  # plain PSNR per component (Y, Cb, Cr), same masking
    offset: tuple[int, int, int]  # the global colour offset tolerated, test - reference, per component
    directions_db: tuple[float, float]  # (reference -> test, test -> reference); IV-PSNR is the minimum


def _psnr(ssd: float, count: float, peak: int) -> float:
    return 10.0 * math.log10(count * peak * peak / (ssd if ssd > 0 else 1.0))


def _check(ref: U16, test: U16, bit_depth: int, mask: NDArray[np.integer] | None) -> None:
    if ref.ndim != 3 or ref.shape[0] != 3:
        raise ValueError(f"pictures must be (3, height, width) YCbCr planes, got shape {ref.shape}")
    if test.shape != ref.shape:
        raise ValueError(f"pictures differ in size: {ref.shape[1:]} and {test.shape[1:]}")
    if not 8 <= bit_depth <= 14:
        raise ValueError(f"bit depth must be 8 to 14 (as the reference software), got {bit_depth}")
    if mask is not None and mask.shape != ref.shape[1:]:
        raise ValueError(f"mask size {mask.shape} differs from the pictures' {ref.shape[1:]}")
    if mask is not None and not mask.any():
        raise ValueError("the mask has no non-zero pixel: nothing to compare")


def global_offset(
    ref: U16,
    test: U16,
    bit_depth: int,
    mask: NDArray[np.integer] | None = None,
    mask_peak: int = 1,
    coef: float = UNNOTICEABLE,
) -> NDArray[np.int32]:
    """Per component round(mean(test - ref)) clipped to +-round(coef * peak); with a mask, the sum weighted
    by the mask over (non-zero pixels x ``mask_peak``)."""
    peak = (1 << bit_depth) - 1
    limit = int(np.rint(np.float32(coef) * np.float32(peak)))
    diff = test.astype(np.int64) - ref.astype(np.int64)
    if mask is None:
        mean = diff.reshape(3, -1).sum(axis=1) / diff[0].size
    else:
        m = mask.astype(np.int64)
        mean = (diff * m).reshape(3, -1).sum(axis=1) / (np.count_nonzero(m) * mask_peak)
    return np.clip(np.rint(mean), -limit, limit).astype(np.int32)


def _one_way(
    src: NDArray[np.int32], other: NDArray[np.int32], mask: NDArray[np.int32] | None, s: int
) -> NDArray[np.float64]:
    """Per-component SSD of every pixel of ``src`` (already offset) against its best match in ``other``:
    a compiled loop over the pixels (:func:`_one_way_kernel`); :func:`one_way_numpy` is the same in numpy,
    kept as the reference the kernel is tested against."""
    pad = np.ascontiguousarray(np.pad(other, ((0, 0), (s, s), (s, s)), mode="edge"))
    m = np.ones(src.shape[1:], np.int32) if mask is None else mask
    valid = np.ascontiguousarray(np.pad(m, s, mode="edge") != 0) if mask is not None else np.ones((1, 1), np.bool_)
    return np.asarray(
        _one_way_kernel(np.ascontiguousarray(src), pad, valid, np.ascontiguousarray(m), s, mask is not None),
        np.float64,
    )


@njit(cache=True, nogil=True)
def _one_way_kernel(
    src: NDArray[np.int32], pad: NDArray[np.int32], valid: NDArray[np.bool_], mask: NDArray[np.int32], s: int,
    masked: bool,
) -> NDArray[np.float64]:  # fmt: skip
    _, h, w = src.shape
    ssd = np.zeros(3, np.float64)
    for y in range(h):
        for x in range(w):
            if masked and mask[y, x] == 0:
                continue
            t0, t1, t2 = src[0, y, x], src[1, y, x], src[2, y, x]
            best = np.int64(1) << 62
            b0 = b1 = b2 = np.int64(0)
            for dy in range(2 * s + 1):  # raster order, strictly better only: the first best wins a tie
                for dx in range(2 * s + 1):
                    if masked and not valid[y + dy, x + dx]:
                        continue
                    d0 = np.int64(t0 - pad[0, y + dy, x + dx])
                    d1 = np.int64(t1 - pad[1, y + dy, x + dx])
                    d2 = np.int64(t2 - pad[2, y + dy, x + dx])
                    err = 4 * d0 * d0 + d1 * d1 + d2 * d2
                    if err < best:
                        best, b0, b1, b2 = err, d0, d1, d2
            wt = mask[y, x] if masked else 1
            ssd[0] += b0 * b0 * wt
            ssd[1] += b1 * b1 * wt
            ssd[2] += b2 * b2 * wt
    return ssd


def one_way_numpy(
    src: NDArray[np.int32], other: NDArray[np.int32], mask: NDArray[np.int32] | None, s: int
) -> NDArray[np.float64]:
    """:func:`_one_way` in numpy: every window offset over the whole picture at once."""
    _, h, w = src.shape
    pad = np.pad(other, ((0, 0), (s, s), (s, s)), mode="edge")
    valid = None if mask is None else np.pad(mask, s, mode="edge") != 0
    best = np.full((h, w), np.iinfo(np.int32).max, np.int32)  # 6 (2^14 - 1)^2 < 2^31: int32 holds it
    match = np.empty_like(src)
    d = np.empty((h, w), np.int32)
    err = np.empty((h, w), np.int32)
    for dy in range(-s, s + 1):  # raster order, strictly better only: the first best wins a tie
        for dx in range(-s, s + 1):
            cand = pad[:, s + dy : s + dy + h, s + dx : s + dx + w]
            np.subtract(src[0], cand[0], out=d)
            np.multiply(d, d, out=err)
            err *= WEIGHTS[0]
            for c in (1, 2):
                np.subtract(src[c], cand[c], out=d)
                d *= d
                err += d
            better = err < best
            if valid is not None:
                better &= valid[s + dy : s + dy + h, s + dx : s + dx + w]
            np.copyto(best, err, where=better)
            np.copyto(match, cand, where=better)
    sq = (src - match).astype(np.int64) ** 2
    if mask is None:
        return sq.reshape(3, -1).sum(axis=1).astype(np.float64)
    return (sq * mask.astype(np.int64)).reshape(3, -1).sum(axis=1).astype(np.float64)


def ivpsnr(
    ref: U16,
    test: U16,
    bit_depth: int,
    mask: NDArray[np.integer] | None = None,
    mask_bit_depth: int | None = None,
    search_range: int = SEARCH_RANGE,
    coef: float = UNNOTICEABLE,
) -> IvPsnr:
    """IV-PSNR of ``test`` against ``ref``: both (3, H, W) YCbCr at ``bit_depth``, chroma at full size
    (see :func:`upsample_420`). ``mask`` (H, W): compare only where it is non-zero, weighted by its value;
    its peak is 2^``mask_bit_depth`` - 1 (default: the pictures' bit depth)."""
    _check(ref, test, bit_depth, mask)
    peak = (1 << bit_depth) - 1
    mask_peak = (1 << (bit_depth if mask_bit_depth is None else mask_bit_depth)) - 1
    offset = global_offset(ref, test, bit_depth, mask, mask_peak, coef)
    r = ref.astype(np.int32)
    t = test.astype(np.int32)
    m = None if mask is None else mask.astype(np.int32)
    if m is None:
        count = float(r[0].size)
        plain = ((r - t).astype(np.int64) ** 2).reshape(3, -1).sum(axis=1)
    else:
        nonzero = int(np.count_nonzero(m))
        count = float(nonzero * mask_peak)
        plain = (((r - t).astype(np.int64) ** 2) * m).reshape(3, -1).sum(axis=1)
    off = offset[:, None, None]
    directions = []
    for src, other, shift in ((r, t, off), (t, r, -off)):
        ssd = _one_way(src + shift, other, m, search_range)
        per = [_psnr(float(ssd[c]), count, peak) for c in range(3)]
        directions.append(sum(wt * p for wt, p in zip(WEIGHTS, per, strict=True)) / sum(WEIGHTS))
    psnr = tuple(_psnr(float(plain[c]), count, peak) for c in range(3))
    return IvPsnr(
        ivpsnr_db=min(directions),
        psnr_db=(psnr[0], psnr[1], psnr[2]),
        offset=(int(offset[0]), int(offset[1]), int(offset[2])),
        directions_db=(directions[0], directions[1]),
    )


def upsample_420(y: U16, cb: U16, cr: U16) -> U16:
    """(3, H, W) planes from 4:2:0: each chroma sample repeated over its 2x2 block (as the reference)."""
    h, w = y.shape
    up = [np.repeat(np.repeat(c, 2, axis=0), 2, axis=1)[:h, :w] for c in (cb, cr)]
    return np.stack([y, up[0], up[1]]).astype(np.uint16)


def ivpsnr_rgb(rendered: NDArray[np.float32], reference: NDArray[np.float32], mask: NDArray[np.bool_]) -> float:
    """IV-PSNR (dB) of a rendered view against its reference, both R'G'B' float in [0, 1] (H, W, 3), on the
    pixels of ``mask``: the pictures as BT.709 limited-range YCbCr at 10 bits, 4:4:4 (our pictures have full
    chroma), the mask as an 8-bit picture (255 inside). Only the mask's bounding box widened by the search
    range is compared, which gives the same figure as the whole picture (no match can come from further
    out), in a fraction of the time for a subject that fills part of the frame."""
    from rigctl.interop.yuv import rgb_to_ycbcr

    ys, xs = np.nonzero(mask)
    if not ys.size:
        raise ValueError("no pixels to score")
    h, w = mask.shape
    s = SEARCH_RANGE
    y0, y1 = max(0, int(ys.min()) - s), min(h, int(ys.max()) + s + 1)
    x0, x1 = max(0, int(xs.min()) - s), min(w, int(xs.max()) + s + 1)
    box = (slice(y0, y1), slice(x0, x1))
    m = np.where(mask[box], 255, 0).astype(np.uint8)
    res = ivpsnr(rgb_to_ycbcr(reference[box], 10), rgb_to_ycbcr(rendered[box], 10), 10, m, mask_bit_depth=8)
    return res.ivpsnr_db
