"""``rigctl bench depth --size WxH``: time and peak memory of one frame set at a given size, measured in a fresh
process (so the peak is that frame set's, with the interpreter and libraries a worker also holds). The frame
set is a rectified grid from the caller (the simulated presenter) scaled to the size: the rig's real 4K
frames cost what a worker will pay, without recording a 4K take."""

from __future__ import annotations

import gc
import logging
import multiprocessing
import resource
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rigctl.depth.grid import Grid
from rigctl.depth.options import DepthOptions
from rigctl.errors import ParameterError

log = logging.getLogger(__name__)


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ParameterError(f"--size: expected WIDTHxHEIGHT such as 3840x2160, got {text!r}") from None
    if not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise ParameterError(f"--size: width and height must be 16..16384, got {text!r}")
    return w, h


def scaled(grid: Grid, d_range: tuple[float, float], width: int, height: int) -> tuple[Grid, tuple[float, float]]:
    """The grid resampled to width x height (focal length and disparities scale with the width)."""
    import cv2

    s = width / grid.shape[1]
    size = (width, height)
    images = {
        n: np.asarray(cv2.resize(v, size, interpolation=cv2.INTER_LINEAR), np.float32) for n, v in grid.images.items()
    }
    out = Grid(list(grid.names), images, dict(grid.offsets), grid.focal_px * s, grid.spacing, grid.doffs * s)
    return out, (d_range[0] * s, d_range[1] * s)


def _peak_rss() -> int:
    """This process's peak resident memory (VmHWM) since it started or since :func:`_reset_peak`."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024  # kB on Linux


def _reset_peak() -> None:
    """Start the peak again from the current resident memory (Linux: 5 > /proc/self/clear_refs)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        log.warning("cannot reset the peak memory counter: the peak includes building the input")


def _measure(make: Callable[[], Any], width: int, height: int, preset: str, cameras: tuple[str, ...] | None) -> dict:
    from rigctl.depth.export import Exporter
    from rigctl.depth.pipeline import TakeProcessor
    from rigctl.depth.sources import OneGrid
    from rigctl.farm.frame import pin_threads

    pin_threads()  # as on a worker
    ds = make()
    grid, d_range = scaled(ds.grid, ds.d_range, width, height)
    del ds
    gc.collect()
    before = _peak_rss()
    _reset_peak()
    opt = DepthOptions(preset=preset, disparity_range=d_range, cameras=cameras)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        # one frame set through the pipeline as a worker runs it: depth, then staged and published by rename
        done = TakeProcessor(OneGrid(grid), opt, exporter=Exporter(Path(tmp), atomic=True)).process(0)
    seconds = time.perf_counter() - t0
    stats = done.report
    return {
        "size": [width, height],
        "preset": preset,
        "cameras": list(stats.cameras),
        "seconds": seconds,
        "timings_s": {"depth": stats.timings_s.depth, "write": stats.timings_s.write},
        "peak_rss_bytes": _peak_rss(),
        "peak_rss_while_building_input_bytes": before,
        "input_bytes": int(sum(v.nbytes for v in grid.images.values())),
    }


def measure_size(
    make: Callable[[], Any], width: int, height: int, preset: str = "best", cameras: tuple[str, ...] | None = None
) -> dict[str, Any]:
    """Run :func:`_measure` in a new process (``make`` builds the dataset there and must be picklable)."""
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(1) as pool:
        return dict(pool.apply(_measure, (make, width, height, preset, cameras)))
