"""What a simulated camera's sensor and encoder do to the rendered picture: the exposure (``exposure_stops``),
the video range with its super-whites and sub-blacks, and for 10-bit formats (Y210, v210) true 10-bit codes,
sensor noise drawn in 10-bit codes and the burnt-in id, packed at delivery.

A 10-bit camera's clean frames (rendered in float, quantised once to 10 bits) are kept packed as a take
stores them, 20 bits a pixel: the render cache of a moving scene is loaded while the cameras stream, and at
twice the 8-bit size (Y210 words) that load starved the capture threads of a busy machine. Each delivered
frame is unpacked into Y210 words, where noise and gain apply with saturating arithmetic, and a v210
camera packs the result into its device buffer (:mod:`rigctl.yuv10_kernels`)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from rigctl.simulators import burnin

from rigctl.exr import bt709_to_linear, linear_to_bt709
from rigctl.interfaces import CaptureFormat
from rigctl.pixfmt import from_rgb, video_range
from rigctl.yuv10 import FLOOR_CODE, PEAK_CODE, is_ten_bit, v210_stride

CODE_SHIFT = 6  # Y210: the 10 significant bits are the high bits of each 16-bit word
_LO, _HI = FLOOR_CODE << CODE_SHIFT, PEAK_CODE << CODE_SHIFT


def encode(rgb: NDArray[np.float32], pixel_format: str, exposure_stops: float) -> NDArray[np.uint8]:
    """Rendered BT.709 code values (nominal white 1) to a camera's clean frame: ``exposure_stops`` scales
    the light (+1 doubles it, through the OETF), clipped at the format's range, not at nominal white."""
    if exposure_stops:
        rgb = linear_to_bt709(bt709_to_linear(rgb) * np.float32(2.0**exposure_stops))
    lo, hi = video_range(pixel_format)
    return from_rgb(np.clip(rgb, lo, hi, out=rgb), pixel_format)  # 10-bit: codes from float, packed


def clean_bytes(fmt: CaptureFormat) -> int:
    """Bytes of one clean frame as kept in memory and in the render cache (10-bit: 20 bits a pixel)."""
    return fmt.stored_bytes_per_frame


def noise_bank(seed: int, sigma: float, fmt: CaptureFormat, count: int) -> list[NDArray[Any]]:
    """``count`` frames of sensor noise (sigma in 8-bit grey levels), one value a sample: 8-bit formats in
    8-bit codes (int16), 10-bit formats in 10-bit codes (four to a grey level) as Y210 words, split into
    what is added and what is subtracted (2 x H x 2W uint16: two saturating passes of one type are some ten
    times faster than one of mixed types)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 3]))
    shape = (fmt.height, fmt.width * 2)
    if not is_ten_bit(fmt.pixel_format):
        return [np.rint(rng.normal(0, sigma, shape)).astype(np.int16) for _ in range(count)]
    bank = []
    for _ in range(count):
        n = np.rint(rng.normal(0, 4 * sigma, shape)).astype(np.int32) << CODE_SHIFT
        bank.append(np.stack([np.maximum(n, 0), np.maximum(-n, 0)]).astype(np.uint16))
    return bank


def deliver10(
    clean: NDArray[np.uint8],
    into: memoryview,
    fmt: CaptureFormat,
    gain: float,
    noise: NDArray[np.uint16] | None,
    scratch: NDArray[np.uint16],
    burn: tuple[int, int, int],
) -> memoryview:
    """A 10-bit camera's frame into ``into`` in its device layout: gain, noise and burn-in on the Y210 words
    (``scratch`` for v210), then packed; returns the frame's bytes."""
    from rigctl.yuv10_kernels import pgroups_to_y210, y210_to_v210

    y210 = fmt.pixel_format == "Y210"
    out = np.frombuffer(into, "<u2", count=scratch.size).reshape(scratch.shape) if y210 else scratch
    pgroups_to_y210(clean.reshape(fmt.height, -1), out)
    if gain != 1.0:  # camera control: Y and chroma scaled about black and the chroma zero, as RGB would be
        codes = (out >> CODE_SHIFT).astype(np.float32)
        zero = np.where(np.arange(out.shape[1]) % 2 == 0, 64.0, 512.0).astype(np.float32)
        scaled = np.clip(np.rint(zero + (codes - zero) * np.float32(gain)), FLOOR_CODE, PEAK_CODE)
        np.copyto(out, scaled.astype(np.uint16) << CODE_SHIFT)
    if noise is not None:
        cv2.add(out, noise[0], dst=out)
        cv2.subtract(out, noise[1], dst=out)
        np.minimum(out, _HI, out=out)
        np.maximum(out, _LO, out=out)
    burnin.burn10(out, fmt.width, *burn)
    if y210:
        return into[: out.nbytes]

    stride = v210_stride(fmt.width)
    dst = np.frombuffer(into, "<u4", count=stride // 4 * fmt.height).reshape(fmt.height, stride // 4)
    y210_to_v210(out, dst)
    return into[: stride * fmt.height]
