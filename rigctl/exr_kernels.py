"""The EXR picture's per-pixel passes compiled (Numba): BT.709 code values to scene-linear light, premultiplied
by the matte clipped to [0, 1]. :func:`rigctl.exr.picture_reference` computes the same with numpy in seven
frame-sized passes and as many temporaries; these two passes around numpy's own power function (vectorised,
faster than any scalar one here, and the reference's: the results are the same bit for bit) read the picture
twice and write nothing but the outputs, over all cores (issue 24: the write's time and memory)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(parallel=True, cache=True, fastmath=False)
def lifted(rgb: np.ndarray, out: np.ndarray, knee: float, lift: float, gain: float) -> None:  # pragma: no cover
    """``out`` = (max(v, knee) + lift) / gain of every code value ``v`` of ``rgb`` (H x W x 3), in float32: what
    the inverse OETF raises to 1 / 0.45 above the knee. NaN stays NaN, as numpy's maximum keeps it."""
    k, add, div = np.float32(knee), np.float32(lift), np.float32(gain)
    h, w = rgb.shape[0], rgb.shape[1]
    for y in prange(h):
        for x in range(w):
            for c in range(3):
                v = rgb[y, x, c]
                out[y, x, c] = ((k if v < k else v) + add) / div


@njit(parallel=True, cache=True, fastmath=False)
def premultiply(  # pragma: no cover  (compiled)
    rgb: np.ndarray, matte: np.ndarray, out: np.ndarray, alpha: np.ndarray, knee: float, slope: float
) -> None:
    """``alpha`` = ``matte`` clipped to [0, 1]; ``out`` (the powers above the knee) becomes the linear light,
    v / slope below the knee, times alpha; float32. A NaN matte or code value gives NaN, as in numpy's path."""
    k, s = np.float32(knee), np.float32(slope)
    h, w = matte.shape
    for y in prange(h):
        for x in range(w):
            a = _unit(matte[y, x])
            alpha[y, x] = a
            for c in range(3):
                out[y, x, c] = _light(rgb[y, x, c], out[y, x, c], a, k, s)


@njit(cache=True, fastmath=False, inline="always")
def _unit(a: np.float32) -> np.float32:  # pragma: no cover  (compiled)
    """The matte clipped to [0, 1] (NaN stays NaN, as numpy's clip keeps it)."""
    zero, one = np.float32(0.0), np.float32(1.0)
    return zero if a < zero else (one if a > one else a)


@njit(cache=True, fastmath=False, inline="always")
def _light(
    v: np.float32, power: np.float32, a: np.float32, knee: np.float32, slope: np.float32
) -> np.float32:  # pragma: no cover
    """Linear light times alpha: v / slope below the knee, the power (made by numpy) above it."""
    return (v / slope if v < knee else power) * a


@njit(cache=True, fastmath=False, inline="always")
def half_bits(f: np.uint32) -> np.uint16:  # pragma: no cover  (compiled)
    """The IEEE half float nearest a float32's bits ``f`` (ties to even), as numpy's float32-to-float16 cast
    gives it: overflow to infinity, underflow through the subnormals to a signed zero, a NaN kept a NaN with
    its significand's top bits."""
    sign = np.uint32((f >> np.uint32(16)) & np.uint32(0x8000))
    exp = f & np.uint32(0x7F800000)
    sig = f & np.uint32(0x007FFFFF)
    if exp >= np.uint32(0x47800000):
        if exp == np.uint32(0x7F800000) and sig != np.uint32(0):
            nan = np.uint32(0x7C00) + (sig >> np.uint32(13))
            return np.uint16(sign + (nan + np.uint32(1) if nan == np.uint32(0x7C00) else nan))
        return np.uint16(sign + np.uint32(0x7C00))
    if exp <= np.uint32(0x38000000):
        if exp < np.uint32(0x33000000):
            return np.uint16(sign)
        # the subnormal significand: shifted 13 and as many more as the exponent is below the half's least
        full = (np.uint32(0x00800000) + sig) >> (np.uint32(113) - (exp >> np.uint32(23)))
        # ties to even, with the bits that shift lost looked for in the original
        if (full & np.uint32(0x00003FFF)) != np.uint32(0x00001000) or (f & np.uint32(0x000007FF)) != np.uint32(0):
            full += np.uint32(0x00001000)
        return np.uint16(sign + (full >> np.uint32(13)))
    h_exp = (exp - np.uint32(0x38000000)) >> np.uint32(13)
    if (sig & np.uint32(0x00003FFF)) != np.uint32(0x00001000):
        sig += np.uint32(0x00001000)
    return np.uint16(sign + h_exp + (sig >> np.uint32(13)))


@njit(parallel=True, cache=True, fastmath=False)
def premultiply_half(  # pragma: no cover  (compiled)
    rgb: np.ndarray,
    matte: np.ndarray,
    powers: np.ndarray,
    out: np.ndarray,
    alpha: np.ndarray,
    knee: float,
    slope: float,
) -> None:
    """:func:`premultiply` written as the half floats an EXR holds (``out`` H x W x 3 and ``alpha`` H x W, the
    bits as uint16, :func:`half_bits`): the float32 products are rounded as numpy's cast rounds them, without
    a float32 frame or numpy's scalar cast (issue 24: the write's picture, 7x faster)."""
    k, s = np.float32(knee), np.float32(slope)
    h, w = matte.shape
    for y in prange(h):
        lin = np.empty(3 * w + w, np.float32)  # the row's products and alphas, read back as bits
        bits = lin.view(np.uint32)
        for x in range(w):
            a = _unit(matte[y, x])
            lin[3 * w + x] = a
            for c in range(3):
                lin[3 * x + c] = _light(rgb[y, x, c], powers[y, x, c], a, k, s)
        for x in range(w):
            alpha[y, x] = half_bits(bits[3 * w + x])
            for c in range(3):
                out[y, x, c] = half_bits(bits[3 * x + c])


@njit(parallel=True, cache=True, fastmath=False)
def depth_planes(  # pragma: no cover  (compiled)
    disparity: np.ndarray, f_spacing: float, doffs: float, scales: np.ndarray, inv_z: np.ndarray, out: np.ndarray
) -> None:
    """A depth EXR's planes from the disparity in one pass: ``inv_z`` = 1 / Z, Z = f * spacing / (d + doffs)
    (0 where there is no estimate, d + doffs <= 0 or Z is not a positive finite number), and ``out[i]`` = the
    disparity (0 where it is not finite) times ``scales[i]``; all in float32, as
    :meth:`rigctl.depth.grid.Grid.depth`, the EXR's 1/Z and :func:`rigctl.disparity_layers.layers` compute
    them with numpy, bit for bit."""
    fs, off = np.float32(f_spacing), np.float32(doffs)
    zero, one = np.float32(0.0), np.float32(1.0)
    h, w = disparity.shape
    for y in prange(h):
        for x in range(w):
            d = disparity[y, x]
            den = d + off
            v = zero
            if np.isfinite(den) and den > zero:
                z = fs / den
                if np.isfinite(z) and z > zero:
                    v = one / z
            inv_z[y, x] = v
            fin = d if np.isfinite(d) else zero
            for i in range(scales.shape[0]):
                out[i, y, x] = fin * scales[i]
