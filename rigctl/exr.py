"""OpenEXR output with named channels and header attributes (OpenCV's EXR codec cannot name channels)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
from numpy.typing import NDArray

from rigctl.errors import TakeError


def write_exr(path: Path, channels: dict[str, NDArray[np.floating]], attributes: dict[str, str] | None = None) -> None:
    """Write a scanline EXR (ZIP) with float32 channels; ``RGB`` may be one H x W x 3 array."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    header.update(attributes or {})
    data = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    tmp = path.with_name(path.name + ".tmp.exr")
    OpenEXR.File(header, data).write(str(tmp))
    tmp.replace(path)


def read_exr(path: Path) -> tuple[dict[str, NDArray[np.float32]], dict[str, object]]:
    """Channels and header of an EXR; a file OpenEXR cannot read is a :class:`TakeError` naming it."""
    try:
        f = OpenEXR.File(str(path))
        return {k: np.asarray(v.pixels, dtype=np.float32) for k, v in f.channels().items()}, dict(f.header())
    except (OSError, RuntimeError, ValueError, TypeError) as exc:  # OpenEXR's errors on a damaged file
        raise TakeError(f"{path}: not a readable EXR file: {exc}") from None
