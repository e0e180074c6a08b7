"""OpenEXR output with named channels and header attributes (OpenCV's EXR codec cannot name channels).

Pictures go out as compositing software and game engines read EXR: scene-linear RGB (the cameras' BT.709
transfer decoded), Rec. 709 primaries with a D65 white in ``chromaticities``, an ``A`` channel from the key
matte with RGB premultiplied by it (what NUKE's Read node and Unreal's Img Media assume), and the frame's
``timeCode`` and the take's ``framesPerSecond``. ACEScg (AP1 primaries) is an option, converted by OpenColorIO.
"""

from __future__ import annotations

import functools
import logging
import os
from collections.abc import Mapping
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR
from numpy.typing import NDArray

from rigctl.errors import DiskFullError, OutputError, ParameterError, TakeError
from rigctl.publish import publishing
from rigctl.timecode import Timecode, is_fractional

log = logging.getLogger(__name__)

# ITU-R BT.709 primaries and D65 white: (red x, y, green x, y, blue x, y, white x, y)
REC709_CHROMATICITIES = (0.640, 0.330, 0.300, 0.600, 0.150, 0.060, 0.3127, 0.3290)
# ACES AP1 primaries (ACEScg) and the ACES white (S-2014-004)
AP1_CHROMATICITIES = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
# the colour spaces a picture can be written in: scene-linear Rec. 709 (default) or ACEScg
COLOURS = {"rec709": REC709_CHROMATICITIES, "acescg": AP1_CHROMATICITIES}

# BT.709 OETF: V = 1.099 L^0.45 - 0.099 above L = 0.018, V = 4.5 L below
_BETA, _ALPHA, _SLOPE = 0.018, 1.099, 4.5


def bt709_to_linear(v: NDArray[np.floating]) -> NDArray[np.float32]:
    """Scene-linear light from BT.709 code values in [0, 1] (the inverse of the camera's OETF)."""
    v = np.asarray(v, dtype=np.float32)
    knee = np.float32(_SLOPE * _BETA)  # 0.081
    high = ((np.maximum(v, knee) + np.float32(_ALPHA - 1)) / np.float32(_ALPHA)) ** np.float32(1 / 0.45)
    return np.where(v < knee, v / np.float32(_SLOPE), high).astype(np.float32, copy=False)


def linear_to_bt709(linear: NDArray[np.floating]) -> NDArray[np.float32]:
    """BT.709 code values of scene-linear light (the camera's OETF)."""
    x = np.asarray(linear, dtype=np.float32)
    high = np.float32(_ALPHA) * np.maximum(x, np.float32(_BETA)) ** np.float32(0.45) - np.float32(_ALPHA - 1)
    return np.where(x < _BETA, x * np.float32(_SLOPE), high).astype(np.float32)


def frame_rate(fps: float) -> Fraction:
    """The exact rational rate: 30000/1001 for 29.97, 25/1 for 25."""
    if is_fractional(fps):
        return Fraction(round(fps) * 1000, 1001)
    return Fraction(fps).limit_denominator(1001)


@functools.cache
def _acescg() -> Any:
    """OpenColorIO's processor from linear Rec. 709 to ACEScg, from its built-in ACES studio config."""
    import PyOpenColorIO as ocio

    config = ocio.Config.CreateFromBuiltinConfig("studio-config-latest")
    return config.getProcessor("Linear Rec.709 (sRGB)", "ACEScg").getDefaultCPUProcessor()


def to_colour(linear: NDArray[np.floating], colour: str) -> NDArray[np.float32]:
    """Scene-linear Rec. 709 RGB in ``colour`` (one of :data:`COLOURS`): ``linear`` itself when it is already
    contiguous float32 Rec. 709 (no copy of a frame for nothing), else a new array."""
    if colour not in COLOURS:
        raise ParameterError(f"--colour {colour!r}: choose {' or '.join(COLOURS)}")
    if colour == "rec709":
        return np.ascontiguousarray(linear, dtype=np.float32)
    out = np.array(linear, dtype=np.float32, order="C")
    _acescg().applyRGB(out)  # in place, on the contiguous copy
    return out


def picture(
    rgb: NDArray[np.floating], matte: NDArray[np.floating] | None, colour: str = "rec709"
) -> dict[str, NDArray[np.float32]]:
    """``RGB`` (scene-linear in ``colour``, premultiplied by the matte) and ``A`` from BT.709 code values and a
    key matte. Without a matte the picture is opaque (``A`` = 1), so every output reads the same way.
    Rec. 709 float32 pictures in two compiled passes around numpy's power (``exr_kernels.py``; issue 24: the
    write's time and memory), bit for bit :func:`picture_reference`'s values (a NaN's sign aside, where both
    the code value and the matte are NaN)."""
    if matte is None or colour != "rec709" or not _compilable(rgb, matte):
        return picture_reference(rgb, matte, colour)
    from rigctl.exr_kernels import lifted, premultiply  # compiled on first use

    knee = _SLOPE * _BETA
    out = np.empty(rgb.shape, np.float32)
    alpha = np.empty(matte.shape, np.float32)
    lifted(rgb, out, knee, _ALPHA - 1, _ALPHA)
    np.power(out, np.float32(1 / 0.45), out=out)  # numpy's, as the reference's
    premultiply(rgb, matte, out, alpha, knee, _SLOPE)
    return {"RGB": out, "A": alpha}


HALF_BAND_ROWS = 64  # rows of the picture made in float32 at a time by :func:`half_picture`


def half_picture(
    rgb: NDArray[np.floating], matte: NDArray[np.floating] | None, colour: str = "rec709"
) -> dict[str, NDArray[np.float16]]:
    """:func:`picture` as the half floats an EXR holds it in (numpy's rounding, as :func:`write_exr`'s), made
    in bands of HALF_BAND_ROWS rows: each pixel's value is its own, so the bytes are the whole picture's, and
    no float32 copy of the frame is held (issue 24: 0.12 GiB at 4K, at the write's peak). Where
    :func:`picture` is compiled, its last pass rounds to half floats itself (``exr_kernels.premultiply_half``,
    numpy's rounding bit for bit): numpy's cast was half of this step's time."""
    h = rgb.shape[0]
    out = {"RGB": np.empty(rgb.shape, np.float16), "A": np.empty(rgb.shape[:2], np.float16)}
    if matte is not None and colour == "rec709" and _compilable(rgb, matte):
        from rigctl.exr_kernels import lifted, premultiply_half  # compiled on first use

        knee = _SLOPE * _BETA
        bits = out["RGB"].view(np.uint16), out["A"].view(np.uint16)
        powers = np.empty((min(h, HALF_BAND_ROWS), *rgb.shape[1:]), np.float32)
        for y0 in range(0, h, HALF_BAND_ROWS):
            rows = slice(y0, y0 + HALF_BAND_ROWS)
            band = powers[: len(rgb[rows])]
            lifted(rgb[rows], band, knee, _ALPHA - 1, _ALPHA)
            np.power(band, np.float32(1 / 0.45), out=band)  # numpy's, as the reference's
            premultiply_half(rgb[rows], matte[rows], band, bits[0][rows], bits[1][rows], knee, _SLOPE)
        return out
    for y0 in range(0, h, HALF_BAND_ROWS):
        rows = slice(y0, y0 + HALF_BAND_ROWS)
        for k, v in picture(rgb[rows], None if matte is None else matte[rows], colour).items():
            out[k][rows] = v
    return out


def _compilable(rgb: NDArray[np.floating], matte: NDArray[np.floating]) -> bool:
    """What the compiled pass takes: float32 H x W x 3 and its H x W matte, both in memory order."""
    return (
        rgb.dtype == np.float32
        and matte.dtype == np.float32
        and rgb.ndim == 3
        and rgb.shape[2] == 3
        and rgb.shape[:2] == matte.shape
        and rgb.flags.c_contiguous
        and matte.flags.c_contiguous
    )


def picture_reference(
    rgb: NDArray[np.floating], matte: NDArray[np.floating] | None, colour: str = "rec709"
) -> dict[str, NDArray[np.float32]]:
    """:func:`picture` with numpy, in a pass per operation: what the compiled pass (``exr_kernels.py``) is
    tested against, and what a picture it does not take (another type, a view, ACEScg) is made with."""
    linear = to_colour(bt709_to_linear(rgb), colour)
    alpha = np.ones(linear.shape[:2], np.float32) if matte is None else np.clip(matte, 0, 1).astype(np.float32)
    return {"RGB": linear * alpha[..., None], "A": alpha}


def picture_attributes(fps: float | None, timecode: Timecode | None, colour: str = "rec709") -> dict[str, object]:
    """The standard attributes of a picture: ``chromaticities`` of ``colour`` and, when known,
    ``framesPerSecond`` and ``timeCode`` (SMPTE 12M packed, with its drop-frame flag)."""
    attrs: dict[str, object] = {"chromaticities": COLOURS[colour]}
    if fps is not None:
        attrs["framesPerSecond"] = frame_rate(fps)
    if timecode is not None:
        h, m, s, f = timecode.fields()
        pair = 0
        if timecode.rate > 30:  # ST 12-1 above 30 fps: the frame-pair number, the pair's second frame flagged
            f, pair = divmod(f, 2)
        attrs["timeCode"] = OpenEXR.TimeCode(h, m, s, f, int(timecode.drop), 0, pair, *([0] * 11))
    return attrs


# Lossless run-length coding, in OpenEXR since 1.0: half ZIP's encoding time for a depth EXR, whose six float32
# disparity layers no lossless codec shrinks much, at 13 to 28 % more bytes (README: issue 24's write)
FAST_LOSSLESS = OpenEXR.RLE_COMPRESSION


@functools.cache
def _encode_threads() -> None:
    """OpenEXR compresses a file's line blocks on its global thread pool, which is empty unless set: one
    thread per core this process may use (the same bytes, about 1.4x faster on two cores at 1920x1080)."""
    OpenEXR.set_global_thread_count(max(1, len(os.sched_getaffinity(0))))


def write_exr(
    path: Path,
    channels: dict[str, NDArray[np.floating]],
    attributes: dict[str, object] | None = None,
    half: tuple[str, ...] = (),
    compression: Any = None,
    durable: bool = True,
) -> None:
    """Write a scanline EXR with float32 channels, or half floats for those named in ``half``; ``RGB`` may be
    one H x W x 3 array. ZIP unless ``compression`` says otherwise (an ``OpenEXR.*_COMPRESSION``).
    ``durable=False``: not fsynced (:func:`rigctl.publish.publishing`), for a caller that makes it so."""
    header: dict[str, object] = {
        "compression": OpenEXR.ZIP_COMPRESSION if compression is None else compression,
        "type": OpenEXR.scanlineimage,
    }
    header.update(attributes or {})
    data = {k: np.ascontiguousarray(v, dtype=np.float16 if k in half else np.float32) for k, v in channels.items()}
    with publishing(path, durable) as tmp:  # a temporary name in the same folder, renamed once whole
        try:
            _encode_threads()
            OpenEXR.File(header, data).write(str(tmp))
        except RuntimeError as exc:  # OpenEXR's way of saying a write failed (a full disk among others)
            full = os.statvfs(tmp.parent).f_bavail * os.statvfs(tmp.parent).f_frsize < (1 << 20)
            raise (DiskFullError if full else OutputError)(
                f"{path}: {'no space left on the device' if full else f'cannot write: {exc}'}; the file was not written"
            ) from None


# Every header attribute of ours is named PREFIX + name, the namespace form OpenImageIO uses (oiio:ColorSpace)
# and our USD stage's attributes share (rigctl:imageSize); the README has the table. Depth EXRs used
# "rigctl." and rendered views "rigctl_" before: read_exr gives a file's old names under the new ones.
PREFIX = "rigctl:"
OLD_PREFIXES = ("rigctl.", "rigctl_")


def our_names(header: dict[str, object]) -> dict[str, object]:
    """``header`` with every attribute of ours under :data:`PREFIX` (an old file's kept under its own name
    too); an attribute already under the new name wins."""
    out = dict(header)
    for key, value in header.items():
        old = next((p for p in OLD_PREFIXES if key.startswith(p)), None)
        if old is not None:
            out.setdefault(PREFIX + key[len(old) :], value)
    return out


# the most any EXR compression expands to (ZIP/deflate tops out near 1032:1, half floats read as float32 x2)
MAX_EXPANSION = 4096


def _check_window(path: Path, header: Mapping[str, object]) -> None:
    window = header.get("dataWindow")
    channels = header.get("channels")
    count = len(channels) if isinstance(channels, list | tuple | dict) else 0
    try:
        (x0, y0), (x1, y1) = np.asarray(window, dtype=np.int64).reshape(2, 2)
    except (TypeError, ValueError):
        raise TakeError(f"{path}: not a readable EXR file: no dataWindow") from None
    pixels = max(0, int(x1) - int(x0) + 1) * max(0, int(y1) - int(y0) + 1)
    need = pixels * max(1, count) * 4
    size = path.stat().st_size
    if need > MAX_EXPANSION * size + (1 << 20):
        raise TakeError(
            f"{path}: EXR header claims a {int(x1) - int(x0) + 1}x{int(y1) - int(y0) + 1} window, "
            f"more than a {size}-byte file can hold: the file is damaged"
        )


def read_exr(path: Path) -> tuple[dict[str, NDArray[np.float32]], dict[str, object]]:
    """Channels and the header; ``RGB`` comes back as one H x W x 3 array, ``A`` on its own. A file OpenEXR
    cannot read is a :class:`TakeError` naming it, and so is a header whose pixels could not come from a file
    of its size (OpenEXR allocates the whole window before it reads a chunk)."""
    try:
        head = OpenEXR.File(str(path), header_only=True).header()
        _check_window(path, head)
        f = OpenEXR.File(str(path))
        channels = {k: np.asarray(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
        header = our_names(dict(f.header()))
    except (OSError, RuntimeError, ValueError, TypeError) as exc:  # OpenEXR's errors on a damaged file
        raise TakeError(f"{path}: not a readable EXR file: {exc}") from None
    rgba = channels.pop("RGBA", None)
    if rgba is not None:
        channels["RGB"], channels["A"] = rgba[..., :3], rgba[..., 3]
    return channels, header
