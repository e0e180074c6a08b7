"""One frame set on a worker: read it from the take on shared storage, rectify it when the take is not
rectified yet, estimate depth with ``rigctl depth``'s own functions and write its outputs atomically.

Everything a task receives is a :class:`FrameJob` of paths and options (a few hundred bytes); everything it
returns is a small dict. Images never leave the worker that reads them.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import shutil
import time
import uuid
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from rigctl.depth.grid import Grid, TakeGrid
from rigctl.depth.run import DepthOptions, Target, depth_grid, planned_range, write_outputs
from rigctl.errors import ParameterError, RigctlError, TakeError

log = logging.getLogger(__name__)

# Thread pools whose size could change the order of floating-point sums: pinned to one thread per worker
# process (the Dask nanny sets the same for the processes it starts), so any worker computes the same bytes.
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
FORMATS = ("exr", "pfm", "png")
PARTIAL_PREFIX = ".partial-"


def frame_name(number: int) -> str:
    """The folder name of a frame set, as ``rigctl depth`` names it."""
    return f"{number:06d}"


@dataclass(frozen=True)
class FrameJob:
    take: str
    out: str  # DIR/depth
    frame: int
    options: DepthOptions
    calibration: str | None = None


def pin_threads() -> None:
    """One thread for OpenCV and the BLAS libraries, fixed seeds: identical results on every worker."""
    import cv2

    for var in THREAD_ENV:
        os.environ[var] = "1"
    cv2.setNumThreads(1)
    cv2.setRNGSeed(0)
    np.random.seed(0)


class RectifyingGrid:
    """Frame sets of a take that is not rectified yet, rectified in memory with a calibration (the grid is the
    one ``rigctl rectify`` then ``rigctl depth`` would see: the same tables and the same 8-bit BGR step)."""

    def __init__(self, take: Path, calibration: Path) -> None:
        from rigctl.rectify import rectifier_for_take
        from rigctl.take.reader import TakeReader

        self.reader = TakeReader(take)
        self.rect = rectifier_for_take(self.reader, calibration)
        rec = self.rect.record()
        self.focal_px = rec.focal_px
        self.spacing = rec.spacing_x_m
        positions = {n: np.asarray(p, float) for n, p in rec.positions_m.items()}
        origin = np.mean([positions[n] for n in self.reader.names], axis=0)
        self.offsets = {
            n: (float((positions[n] - origin)[0] / self.spacing), float((positions[n] - origin)[1] / self.spacing))
            for n in self.reader.names
        }
        self.names = sorted(self.reader.names, key=lambda n: (self.offsets[n][1], self.offsets[n][0]))
        self.folder = take

    def frame_numbers(self) -> list[int]:
        return [s.number for s in self.reader.complete_sets()]

    def grid(self, number: int) -> Grid:
        from rigctl.rectify import frame_bgr

        sets = {s.number: s for s in self.reader.complete_sets()}
        if number not in sets:
            raise ParameterError(f"{self.folder}: frame set {number} is not complete or does not exist")
        images = {n: self.rect.frame(n, frame_bgr(self.reader, n, sets[number].members[n])) for n in self.names}
        meta: dict[str, str | int] = {"take": str(self.folder), "frame": number}
        return Grid(list(self.names), images, dict(self.offsets), self.focal_px, self.spacing, meta=meta)


def is_rectified(take: Path) -> bool:
    """True when ``rigctl depth`` can read the take as it is (rectified, or an ideal simulated take)."""
    try:
        TakeGrid(take)
    except TakeError:
        return False
    return True


@lru_cache(maxsize=4)
def open_source(take: str, calibration: str | None) -> TakeGrid | RectifyingGrid:
    """The take as grids, opened once per worker process (the remap tables are built once, not per frame)."""
    if calibration is None:
        return TakeGrid(Path(take))
    return RectifyingGrid(Path(take), Path(calibration))


def publish(tmp: Path, final: Path) -> None:
    """Move every finished file into the frame's folder by rename: a reader sees a whole file or none."""
    final.mkdir(parents=True, exist_ok=True)
    for f in sorted(tmp.iterdir()):
        os.replace(f, final / f.name)
    tmp.rmdir()


@dataclass
class FrameDone:
    """What a worker reports of one frame set: the cameras written, the range searched and why, timings."""

    cameras: list[str]
    disparity_range_px: tuple[float, float]
    range_source: str
    depth_s: float
    write_s: float
    load_s: float = 0.0

    def to_json(self) -> dict[str, object]:
        return {
            "cameras": self.cameras,
            "disparity_range_px": list(self.disparity_range_px),
            "range_source": self.range_source,
            "timings_s": {"depth": self.depth_s, "write": self.write_s, "load": self.load_s},
        }


def compute_frame(job: FrameJob) -> FrameDone:
    """Rectify (when needed), depth and export of one frame set; returns timings and small statistics."""
    t0 = time.perf_counter()
    source = open_source(job.take, job.calibration)
    grid = source.grid(job.frame)
    # the pictures carry the rate and the frame set's timecode, as rigctl depth writes them
    sets = {s.number: s for s in source.reader.frame_sets}
    target = Target(Path(job.out), "frames", job.frame, source.reader.fps, source.reader.set_timecode(sets[job.frame]))
    done = depth_and_publish(grid, job.options, target)
    done.load_s = time.perf_counter() - t0 - done.depth_s - done.write_s
    return done


def depth_and_publish(grid: Grid, options: DepthOptions, final: Target) -> FrameDone:
    """Depth of every requested camera of ``grid``, written to a temporary folder beside ``out/name`` and then
    renamed into it file by file (``rigctl bench depth --size`` measures exactly this)."""
    t0 = time.perf_counter()
    results = depth_grid(grid, options)
    t_depth = time.perf_counter() - t0
    d_range, why = planned_range(grid, options)
    name = frame_name(final.frame)
    tmp = final.out / f"{PARTIAL_PREFIX}{name}-{uuid.uuid4().hex[:12]}"
    staging = dataclasses.replace(final, out=tmp, flat=True)
    try:
        for cam, res in results.items():
            write_outputs(staging, cam, grid, res, d_range, FORMATS)
        publish(tmp, final.out / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    d_lo, d_hi = float(d_range[0]), float(d_range[1])
    return FrameDone(list(results), (d_lo, d_hi), why, t_depth, time.perf_counter() - t0 - t_depth)


def run_frame(job: FrameJob) -> dict[str, Any]:
    """The Dask task: never raises for a bad frame (a failed frame is reported, the others go on)."""
    pin_threads()
    t0 = time.perf_counter()
    entry: dict[str, Any] = {"frame": job.frame, "worker": worker_address()}
    try:
        entry.update(compute_frame(job).to_json())
        entry["status"] = "done"
    except (RigctlError, OSError, ValueError, MemoryError) as exc:
        log.warning("frame %s failed: %s", job.frame, exc)
        entry.update(status="failed", error=one_line(exc))
    entry["seconds"] = time.perf_counter() - t0
    return entry


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if isinstance(exc, RigctlError) else f"{type(exc).__name__}: {text}"


def worker_address() -> str:
    """The Dask worker running this task (``local`` outside a cluster)."""
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except ValueError:
        return "local"
