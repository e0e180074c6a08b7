"""Issue 24's memory of a worker's chunk: N frame sets of the moving realistic presenter (the simulator's
default motion) resampled to a size, through ``TakeProcessor`` as a farm worker runs a chunk (temporal
state carried, each frame set staged and published by rename, and let go of before the next one starts, as
``rigctl.farm.frame.run_chunk`` does). Prints, per frame set, the depth's and the write's resident peaks
(the kernel's peak counter restarted per phase: each counts what was held when it began), their seconds,
and what the process holds after it.

A measurement that keeps the previous frame set (its pictures and results) alive through the next one's
depth, as a loop variable does, adds it to the later frame set's peak: about 0.4 GiB at 3840x2160, which
the figures in the README before session 24 included.

    python benchmarks/chunk_memory.py [--size 3840x2160] [--frames 2] [--trim]

``--trim`` gives glibc's freed pages back (``malloc_trim(0)``) before each frame set, to tell what the
allocator keeps from what the frame set needs.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import tempfile
import time
from pathlib import Path
from typing import Any

from rigctl.depth.export import Exporter
from rigctl.depth.grid import Grid
from rigctl.depth.options import DepthOptions
from rigctl.depth.pipeline import TakeProcessor
from rigctl.farm.frame import pin_threads
from rigctl.farm.membench import parse_size, phase_peak, scaled
from rigctl.simulated_presenter import presenter, presenter_video

GIB = 2**30


def resident() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


class Resampled:
    """The take's frame sets resampled to ``size`` as 8-bit BGR, as a rectified take's frames reach a worker."""

    flat = False
    name = "moving realistic presenter"

    def __init__(self, take: Any, frames: int, size: tuple[int, int]) -> None:
        self.take, self.frames, self.size = take, frames, size
        g = take.grid(0)
        s = size[0] / g.shape[1]
        self.names = list(g.names)
        self.focal_px, self.spacing, self.doffs = g.focal_px * s, g.spacing, g.doffs * s
        self.disparity_range = None

    def frame_numbers(self) -> list[int]:
        return list(range(self.frames))

    def timing(self, number: int) -> tuple[None, None]:
        return None, None

    def grid(self, number: int) -> Grid:
        g, _ = scaled(self.take.grid(number), (0.0, 1.0), *self.size, eight_bit=True)
        return g


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="3840x2160")
    ap.add_argument("--frames", type=int, default=2)
    ap.add_argument("--trim", action="store_true", help="malloc_trim(0) before each frame set")
    ns = ap.parse_args()
    size = parse_size(ns.size)
    pin_threads()  # as on a worker: one allocator arena, the kernels' threads
    source = Resampled(presenter_video(True, ns.frames), ns.frames, size)
    s = size[0] / source.take.grid(0).shape[1]
    lo, hi = presenter(False).d_range
    opt = DepthOptions(preset="best", disparity_range=(lo * s, hi * s))
    trim = ctypes.CDLL(None).malloc_trim if ns.trim else None
    print(f"{ns.frames} frame sets at {size[0]}x{size[1]}, nine cameras, best; trim {'on' if trim else 'off'}")
    with tempfile.TemporaryDirectory() as tmp:
        processor = TakeProcessor(source, opt, exporter=Exporter(Path(tmp), atomic=True))
        for n in range(ns.frames):
            if trim is not None:
                trim(0)
            start = resident()
            t0 = time.perf_counter()
            computed, peak_depth = phase_peak(lambda n=n: processor.computed(n))
            t1 = time.perf_counter()
            done, peak_write = phase_peak(computed.write)
            t2 = time.perf_counter()
            del computed, done  # as a worker: the frame set is let go of before the next
            gc.collect()
            print(
                f"frame set {n}: held at start {start / GIB:.2f} GiB; depth peak {peak_depth / GIB:.2f} GiB "
                f"({t1 - t0:.0f} s); write peak {peak_write / GIB:.2f} GiB ({t2 - t1:.0f} s); "
                f"held after {resident() / GIB:.2f} GiB",
                flush=True,
            )


if __name__ == "__main__":
    main()
