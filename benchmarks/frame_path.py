"""Disk to matcher: the bytes written into new memory and the time to turn a take's frames into the 8-bit BGR
pictures the semi-global matcher reads, for the frame path before and after the direct one, in one run.

Before (kept callable here as it was): the essence file opened for every frame, the frame decoded to float
RGB (``to_rgb``), the grid holding float RGB, and the matcher's ``to_u8`` turning it back into 8-bit BGR.
After: the reader's one open file per camera, the grid holding the frame bytes, and ``Grid.bgr8`` converting
them once, directly (packed 4:2:2 through one ``cv2.transform``; a rectified BGR take needs no conversion).

Bytes are measured, not estimated: every buffer numpy, OpenCV (its Python arrays are numpy's) and ``os.pread``
allocate is seen by ``tracemalloc``; the path runs under a line tracer that adds, line by line, how far the
traced memory rose above where the line started (so temporaries made and freed within one line count once, at
their largest: a lower bound, exact for a line that allocates without freeing). Time is measured separately,
without the tracer. Takes are written to a temporary folder and read back from the page cache, so the time is
the CPU's, not the disk's. Run: ``python benchmarks/frame_path.py [--size 1920x1080] [--frames 4]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
import tracemalloc
import zlib
from collections.abc import Callable
from pathlib import Path
from types import FrameType

import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import TakeGrid
from rigctl.interfaces import Frame, FrameFlags
from rigctl.pixfmt import from_rgb, to_rgb
from rigctl.take.manifest import TAKE_SPEC, Manifest, Rectification, write_manifest
from rigctl.take.reader import TakeReader
from rigctl.take.writer import CameraWriter

CAMERAS = ("r0c0", "r0c1", "r0c2")
Path_ = Callable[[Path, int], dict[str, NDArray[np.uint8]]]


def allocated(fn: Path_, folder: Path, number: int) -> int:
    """Bytes ``fn`` allocates, traced line by line (see the module's docstring)."""
    total = 0
    start = 0

    def tracer(frame: FrameType, event: str, arg: object) -> object:
        nonlocal total, start
        if event in ("line", "return", "call"):
            current, peak = tracemalloc.get_traced_memory()
            total += max(0, peak - start)
            tracemalloc.reset_peak()
            start = current
        return tracer

    tracemalloc.start()
    start = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    sys.settrace(tracer)
    try:
        out = fn(folder, number)
    finally:
        sys.settrace(None)
        total += max(0, tracemalloc.get_traced_memory()[1] - start)
        tracemalloc.stop()
    del out
    return total


def make_take(folder: Path, pixel_format: str, width: int, height: int, frames: int) -> Path:
    rng = np.random.default_rng(0)
    folder.mkdir(parents=True)
    per_pixel = {"UYVY": 2, "BGR3": 3}[pixel_format]
    for ci, name in enumerate(CAMERAS):
        writer = CameraWriter(name, folder, 25.0, sync_interval_s=0)
        for i in range(frames):
            rgb = rng.random((height // 8, width // 8, 3), dtype=np.float32).repeat(8, 0).repeat(8, 1)
            data = from_rgb(rgb, pixel_format)
            t = 10**12 + i * 40_000_000 + ci
            writer.write(Frame(name, i, t, t, FrameFlags(0), memoryview(data.reshape(-1).data)), i)
        writer.close()
    write_manifest(
        folder,
        Manifest(
            spec=TAKE_SPEC,
            take=folder.name,
            status="complete",
            format={
                "width": width,
                "height": height,
                "pixel_format": pixel_format,
                "fps": 25.0,
                "bytes_per_frame": width * height * per_pixel,
            },
            cameras={n: {"essence": f"{n}.essence", "index": f"{n}.index", "frames": frames} for n in CAMERAS},
            rectification=Rectification(
                calibration_sha256="0" * 64,
                R=np.eye(3).tolist(),
                K=np.eye(3).tolist(),
                image_size=[width, height],
                spacing_x_m=0.1,
                spacing_y_m=0.1,
                focal_px=1000.0,
                lattice_residual_mm=0.0,
                positions_m={n: [0.1 * i, 0.0, 0.0] for i, n in enumerate(CAMERAS)},
            ),
        ),
    )
    return folder


# ---- before: the frame path as it was -------------------------------------------------------------------
def _old_frame_bytes(reader: TakeReader, name: str, i: int) -> NDArray[np.uint8]:
    rec = reader.index[name][i]
    size, offset = int(rec["size"]), int(rec["offset"])
    fd = os.open(reader.essence_path(name), os.O_RDONLY)  # opened and closed for every frame
    try:
        data = os.pread(fd, size, offset)
    finally:
        os.close(fd)
    if rec["crc"] and zlib.crc32(data) != int(rec["crc"]):
        raise RuntimeError("checksum")
    return np.frombuffer(data, dtype=np.uint8)


def _old_to_u8(img: NDArray[np.float32]) -> NDArray[np.uint8]:
    return np.ascontiguousarray(np.clip(img[..., ::-1] * 255 + 0.5, 0, 255).astype(np.uint8))


def before(folder: Path, number: int) -> dict[str, NDArray[np.uint8]]:
    reader = TakeReader(folder)
    members = {s.number: s for s in reader.complete_sets()}[number].members
    images = {  # the grid held float RGB ...
        n: to_rgb(_old_frame_bytes(reader, n, members[n]), reader.pixel_format, reader.width, reader.height)
        for n in reader.names
    }
    return {n: _old_to_u8(images[n]) for n in reader.names}  # ... and the matcher made 8-bit BGR of it again


# ---- after: the direct path ---------------------------------------------------------------------------------
def after(folder: Path, number: int) -> dict[str, NDArray[np.uint8]]:
    grid = TakeGrid(folder).grid(number)
    return {n: grid.bgr8(n) for n in grid.names}


def measure(folder: Path, frames: int, rounds: int) -> dict[str, tuple[float, int]]:
    """Per path: median seconds and median bytes allocated per frame set. The two paths are timed in turn,
    frame set by frame set, so a machine busy with something else slows both alike."""
    paths = {"before": before, "after": after}
    for fn in paths.values():
        fn(folder, 0)  # warm: page cache, imports, OpenCV's first call
    times: dict[str, list[float]] = {k: [] for k in paths}
    for _ in range(rounds):
        for n in range(frames):
            for key, fn in paths.items():
                t0 = time.perf_counter()
                fn(folder, n)
                times[key].append(time.perf_counter() - t0)
    return {
        key: (statistics.median(times[key]), int(statistics.median(allocated(fn, folder, n) for n in range(frames))))
        for key, fn in paths.items()
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--rounds", type=int, default=3, help="timed passes over the frame sets")
    args = ap.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    picture = width * height * 3  # one 8-bit BGR picture: the unit of the counts below
    print(f"{len(CAMERAS)} cameras, {width}x{height}, median over {args.frames} frame sets x {args.rounds} rounds:")
    print("time from the take's files (page cache) to the matcher's 8-bit BGR input, bytes allocated on the way")
    with tempfile.TemporaryDirectory() as tmp:
        for fmt, what in (("UYVY", "as recorded (UYVY)"), ("BGR3", "rectified (BGR)")):
            folder = make_take(Path(tmp) / fmt, fmt, width, height, args.frames)
            old, new = before(folder, 0), after(folder, 0)
            diff = np.stack([np.abs(old[n].astype(np.int16) - new[n]) for n in CAMERAS])
            m = measure(folder, args.frames, args.rounds)
            (t_old, b_old), (t_new, b_new) = m["before"], m["after"]
            per_cam = len(CAMERAS) * picture
            print(
                f"take {what}: matcher input before and after differs in {np.count_nonzero(diff)} of {diff.size} "
                f"values, by at most {diff.max()} (before rounded x.5 up, the one to_u8 rounds half to even)"
            )
            print(f"  before  {t_old * 1e3:8.1f} ms  {b_old / 1e6:8.1f} MB  ({b_old / per_cam:5.2f} pictures a camera)")
            print(f"  after   {t_new * 1e3:8.1f} ms  {b_new / 1e6:8.1f} MB  ({b_new / per_cam:5.2f} pictures a camera)")
            print(f"  after / before: time {t_new / t_old:.2f}x, bytes {b_new / max(b_old, 1):.2f}x")


if __name__ == "__main__":
    main()
