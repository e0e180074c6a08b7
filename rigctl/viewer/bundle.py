"""What the page renders from: the take's description (``take.json``) and one binary bundle per frame set.

A bundle holds *every* camera's colour and disparity of one frame set in one response, so the page can only
ever upload a frame set's colour together with that same frame set's disparity. Layout (little-endian)::

    b"RGFS"  u32 header length  JSON header (padded with spaces to a multiple of 4)
    per camera, in the header's order: RGBA8 texels (W x H x 4), then float32 disparity (W x H)

The texels are exactly those ``rigctl.render.warp.prepare`` gives the CPU renderer (RGB and key alpha,
``x * 255 + 0.5`` saturated); the disparity is the PFM's with ``NONE`` (-1e6) where there is no estimate.
"""

from __future__ import annotations

import json
import logging
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np

from rigctl.errors import ParameterError, TakeError
from rigctl.render.inputs import RenderInput, _row_col
from rigctl.render.kernels import NONE
from rigctl.viewer.makeahead import MakeAhead

log = logging.getLogger(__name__)

MAGIC = b"RGFS"
CACHE = 16  # bundles kept in memory: the page's read-ahead plus a little
AHEAD = 8  # bundles made ahead of the last one asked for
CLOSE_WAIT_S = 30.0  # the longest close waits for the bundle being made (seconds at UHD)
MEMORY = 1 << 31  # bytes of bundles kept at most: 16 of the paper's UHD rig (600 MB each) would be 9.5 GB


def _not_finite(value: Any, where: str = "") -> str | None:
    """Where in a JSON-able ``value`` its first number that is not finite is (``cameras[r1c0].offset[1]``)."""
    if isinstance(value, float):
        return None if math.isfinite(value) else where
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        if isinstance(item, dict) and "name" in item:
            key = str(item["name"])  # a camera by its name
        found = _not_finite(item, f"{where}.{key}" if isinstance(value, dict) else f"{where}[{key}]")
        if found is not None:
            return found.lstrip(".")
    return None


def _u8(a: np.ndarray) -> np.ndarray:
    return np.clip(a.astype(np.float32) * np.float32(255.0) + np.float32(0.5), 0, 255).astype(np.uint8)


class Bundles:
    """The take's frame sets as bundles, made on first request and kept in a small LRU cache."""

    def __init__(self, source: Path, disparity: Path) -> None:
        self.input = RenderInput(source, disparity, refuse_unestimated=False)  # an empty frame is shown empty
        self.numbers = self.input.select(None)
        first = self.input.frame(self.numbers[0])
        self.height, self.width = first.shape
        size = len(first.views) * self.height * self.width * 8  # RGBA8 and float32 disparity a camera
        self.cache = max(2, min(CACHE, MEMORY // size))
        self.ahead = min(AHEAD, self.cache - 1)
        self.info = self._describe(first)
        where = _not_finite(self.info)
        if where is not None:  # JSON has no inf or NaN: the page could not read take.json at all
            raise TakeError(
                f"{source}: {where} of the take's description is not a finite number (the grid's spacings or "
                "the rectification's positions are out of range)"
            )
        self.made = MakeAhead(self._make, self.cache)

    def _describe(self, frame: Any) -> dict[str, Any]:
        views = frame.views
        names = list(views)
        rc = np.array([_row_col(n) for n in names], float)
        off = np.array([views[n].offset for n in names], float)
        design = np.column_stack([np.ones(len(names)), rc[:, 1], rc[:, 0]])
        coef, *_ = np.linalg.lstsq(design, off, rcond=None)
        fps = 25.0
        if (self.input.source / "take.yaml").is_file():
            from rigctl.take.manifest import read_manifest

            fps = float(read_manifest(self.input.source).format.fps)
        timecodes = [self.input.frames.timing(n)[1] for n in self.numbers]
        cameras = [
            {"name": n, "row": int(r), "col": int(c), "offset": list(views[n].offset)}
            for n, (r, c) in zip(names, rc.tolist(), strict=True)
        ]
        cols, rows = rc[:, 1], rc[:, 0]
        return {
            "width": self.width,
            "height": self.height,
            "frames": self.numbers,
            "fps": fps,
            "timecodes": [None if tc is None else str(tc) for tc in timecodes],
            "cameras": cameras,
            # grid units (1, col, row) @ fit -> (u, v) in horizontal spacings, as rigctl render maps --at
            "fit": coef.tolist(),
            "limits": {"col": [cols.min() - 1, cols.max() + 1], "row": [rows.min() - 1, rows.max() + 1]},
            "spacing_m": frame.spacing,
            "focal_px": frame.focal_px,
        }

    def get(self, number: int) -> bytes:
        """Frame set ``number``'s bundle; the ones after it are made meanwhile on one thread of their own (a
        bundle costs about as much as ``rigctl render`` reading the frame: decoding and keying nine images)."""
        if number not in self.numbers:
            raise ParameterError(f"frame set {number} is not one of the take's with a disparity")
        at = self.numbers.index(number)
        end = at + 1 + self.ahead
        ahead = self.numbers[at + 1 : end] + self.numbers[: max(0, end - len(self.numbers))]
        return self.made.get(number, ahead)

    def close(self, wait_s: float = CLOSE_WAIT_S) -> None:
        """Drop the bundles queued ahead and end the thread that makes them (:meth:`MakeAhead.close`)."""
        self.made.close(wait_s)

    def _make(self, number: int) -> bytes:
        frame = self.input.frame(number)
        names, chunks, spread, boxes = [], [], [], []
        for v in frame.views.values():
            if v.disparity is None:
                continue
            rgba = np.empty((*v.alpha.shape, 4), np.uint8)
            rgba[..., :3] = _u8(v.rgb)
            rgba[..., 3] = _u8(v.alpha)
            disp = np.where(np.isfinite(v.disparity), v.disparity, NONE).astype("<f4")
            half = disp[::2, ::2]
            valid = half[half > NONE]
            if valid.size:
                spread.append(float(valid.max() - valid.min()))
            rows, cols = np.nonzero(half > NONE)
            # the half-resolution samples that hold a disparity lie in this box: the splat draws no others
            box = [cols.min(), rows.min(), cols.max() + 1, rows.max() + 1] if rows.size else [0, 0, 0, 0]
            boxes.append([int(b) for b in box])
            names.append(v.name)
            chunks += [rgba.tobytes(), disp.tobytes()]
        # the renderer's bound on a disocclusion (warp.Renderer.max_gap): from every source of the frame
        max_gap = int(max(spread, default=0.0) * 1.5 / 2) + 4
        header = json.dumps({"number": number, "cameras": names, "width": self.width, "height": self.height,
                             "max_gap": max_gap, "boxes": boxes}).encode()  # fmt: skip
        header += b" " * (-len(header) % 4)
        return b"".join([MAGIC, struct.pack("<I", len(header)), header, *chunks])
