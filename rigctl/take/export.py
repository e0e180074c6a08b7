"""``rigctl take export``: frame sets as images, 8-bit PNG or scene-linear EXR, in a layout of rigctl.layout.

A damaged frame stops the export (naming file and byte) unless the reader skips damaged frames; then it is
left out and listed in ``DIR/export.json`` under ``skipped_damaged``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from rigctl.errors import ParameterError, TakeError
from rigctl.exr import picture, picture_attributes, to_colour, write_exr
from rigctl.keying import Keyer
from rigctl.layout import check_layout, output_path
from rigctl.publish import publish_json, publish_png
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
    layout: str = "frames",
    colour: str = "rec709",
) -> dict[str, int]:
    """Write every member of the chosen frame sets; returns counts of images written and members missing.

    PNG holds the camera's BT.709 picture as captured (8-bit); EXR holds it scene-linear with the soft key's
    coverage as ``A`` and the subject's unmixed colour premultiplied by it as RGB, ``chromaticities``,
    ``framesPerSecond`` and the frame's ``timeCode``.
    """
    if fmt not in ("png", "exr"):
        raise ParameterError(f"--format {fmt!r}: choose png or exr")
    check_layout(layout)  # an unknown layout is refused before any work
    to_colour(np.zeros((1, 3), np.float32), colour)  # and an unknown colour space
    sets = reader.frame_sets
    if not sets:
        raise TakeError(f"{reader.folder}: the take holds no frames")
    chosen = parse_range(frames, len(sets))
    keyer = Keyer()
    written = missing = 0
    for k, n in enumerate(chosen):
        fs = sets[n]
        tc = reader.set_timecode(fs)
        for name in reader.names:
            if name not in fs.members:
                missing += 1
                continue
            image = reader.image_or_none(name, fs.members[name], "bgr8" if fmt == "png" else "float")
            if image is None:
                continue  # damaged, skipped: listed in reader.damaged
            path = output_path(out, layout, n, name, f".{fmt}")
            if fmt == "png":
                publish_png(path, image)
            else:
                rgb = np.asarray(image, np.float32)
                attrs = picture_attributes(reader.fps, tc, colour)
                attrs.update({"rigctl:camera": name, "rigctl:frame_set": str(n)})
                key = keyer.soft(rgb)  # A: the subject's coverage; RGB: its unmixed colour, premultiplied
                write_exr(path, picture(key.foreground, key.alpha, colour), attrs)
            written += 1
        if progress:
            progress(k + 1, len(chosen))
    result = {"images": written, "missing": missing, "sets": len(chosen), "skipped_damaged": len(reader.damaged)}
    if reader.damaged:
        skipped = [d.model_dump(exclude_none=True) for d in reader.damaged]
        manifest = {"take": str(reader.folder), **result, "skipped_damaged": skipped}
        publish_json(out / "export.json", manifest)
    return result
