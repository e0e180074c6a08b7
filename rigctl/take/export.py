"""``rigctl take export``: frame sets as images, ``DIR/<frame>/<camera>.png`` (8-bit) or ``.exr`` (float).

A damaged frame stops the export (naming file and byte) unless the reader skips damaged frames; then it is
left out and listed in ``DIR/export.json`` under ``skipped_damaged``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from rigctl.errors import ParameterError, TakeError
from rigctl.exr import write_exr
from rigctl.take.reader import TakeReader


def parse_range(text: str | None, count: int) -> range:
    """``N`` or ``A-B`` (inclusive, frame-set numbers from 0) -> range; None -> every set."""
    if text is None:
        return range(count)
    try:
        if "-" in text:
            a, b = (int(v) for v in text.split("-", 1))
        else:
            a = b = int(text)
    except ValueError:
        raise ParameterError(f"--frames {text!r}: expected N or A-B, e.g. 0-24") from None
    if a < 0 or b < a:
        raise ParameterError(f"--frames {text!r}: need 0 <= A <= B")
    if a >= count:
        raise ParameterError(f"--frames {text!r}: the take has {count} frame sets (0-{count - 1})")
    return range(a, min(b, count - 1) + 1)


def export_take(
    reader: TakeReader,
    out: Path,
    frames: str | None = None,
    fmt: str = "png",
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, int]:
    """Write every member of the chosen frame sets; returns counts of images written and members missing."""
    if fmt not in ("png", "exr"):
        raise ParameterError(f"--format {fmt!r}: choose png or exr")
    sets = reader.frame_sets
    if not sets:
        raise TakeError(f"{reader.folder}: the take holds no frames")
    chosen = parse_range(frames, len(sets))
    written = missing = 0
    for k, n in enumerate(chosen):
        fs = sets[n]
        folder = out / f"{n:06d}"
        folder.mkdir(parents=True, exist_ok=True)
        for name in reader.names:
            if name not in fs.members:
                missing += 1
                continue
            rgb = reader.frame_rgb_or_none(name, fs.members[name])
            if rgb is None:
                continue  # damaged, skipped: listed in reader.damaged
            if fmt == "png":
                bgr = np.clip(np.rint(rgb[..., ::-1] * 255.0), 0, 255).astype(np.uint8)
                if not cv2.imwrite(str(folder / f"{name}.png"), bgr):
                    raise TakeError(f"{folder / (name + '.png')}: cannot write")
            else:
                write_exr(folder / f"{name}.exr", {"RGB": rgb}, {"rigctl:camera": name, "rigctl:frame_set": str(n)})
            written += 1
        if progress:
            progress(k + 1, len(chosen))
    result = {"images": written, "missing": missing, "sets": len(chosen), "skipped_damaged": len(reader.damaged)}
    if reader.damaged:
        manifest = {"take": str(reader.folder), **result, "skipped_damaged": reader.damaged}
        (out / "export.json").write_text(json.dumps(manifest, indent=1))
    return result
