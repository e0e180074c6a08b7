"""One chunk of consecutive frame sets on a worker: the take-level pipeline (:mod:`rigctl.depth.pipeline`)
over the chunk, from the take's range decided before any chunk was handed out, its outputs published
atomically frame set by frame set.

Everything a task receives is a :class:`ChunkJob` of paths, frame numbers and options (a few hundred bytes);
everything it returns is one typed ledger entry per frame set. Images never leave the worker that reads
them."""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from rigctl.allocator import limit_arenas
from rigctl.depth.export import DEFAULT_FORMATS, Exporter, frame_name
from rigctl.depth.grid import TakeGrid
from rigctl.depth.options import DepthOptions
from rigctl.depth.pipeline import ChunkEnd, FrameDone, TakeProcessor
from rigctl.depth.sources import FrameSource, open_source
from rigctl.depth.take_range import RangeDecision, SearchState, decide_range
from rigctl.errors import RigctlError, TakeError
from rigctl.farm.ledger import FrameEntry

log = logging.getLogger(__name__)

# Thread pools whose size could change the order of floating-point sums: pinned to one thread per worker
# process (the Dask nanny sets the same for the processes it starts), so any worker computes the same bytes.
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
FAILURES = (RigctlError, OSError, ValueError, MemoryError)

__all__ = ["ChunkJob", "frame_name", "is_rectified", "pin_threads", "run_chunk", "take_range"]


@dataclass(frozen=True)
class ChunkJob:
    take: str
    out: str  # DIR/depth
    frames: tuple[int, ...]
    options: DepthOptions
    decision: RangeDecision
    state: SearchState
    calibration: str | None = None
    formats: tuple[str, ...] = DEFAULT_FORMATS


def pin_threads() -> None:
    """One allocator arena (:mod:`rigctl.allocator`), one thread for the BLAS libraries, OpenCV as many as
    the compiled kernels (numba's), fixed seeds: identical results on every worker. OpenCV's results here do
    not depend on its thread count (its semi-global matcher cuts every image into four stripes whatever the
    threads; the filters compute each pixel alike), so a worker need not run the matcher, a third of the
    depth time, on one thread (issue 24):
    ``test_outputs_do_not_depend_on_opencvs_threads`` holds a frame set's files byte-identical at 1, 2 and 3."""
    import cv2
    import numba

    limit_arenas()  # before the kernels' and OpenCV's threads first allocate
    for var in THREAD_ENV:
        os.environ[var] = "1"
    cv2.setNumThreads(int(numba.get_num_threads()))
    cv2.setRNGSeed(0)
    np.random.seed(0)


def is_rectified(take: Path) -> bool:
    """True when ``rigctl depth`` can read the take as it is (rectified, or an ideal simulated take)."""
    try:
        TakeGrid(take)
    except TakeError:
        return False
    return True


@lru_cache(maxsize=4)
def cached_source(take: str, calibration: str | None) -> FrameSource:
    """The take as grids, opened once per worker process (the remap tables are built once, not per chunk)."""
    return open_source(Path(take), Path(calibration) if calibration else None)


def take_range(take: str, calibration: str | None, options: DepthOptions) -> RangeDecision | RigctlError:
    """The Dask task run before the chunks: the take's range, decided once on a worker (the client reads no
    image). A refusal (a plan too close to turn into disparities, a damaged take) is returned, not raised: the
    client raises it as its one line, and distributed logs no "Compute Failed" and traceback before it."""
    pin_threads()
    try:
        return decide_range(cached_source(take, calibration), options)
    except RigctlError as exc:
        return exc


def run_chunk(job: ChunkJob) -> tuple[list[tuple[int, FrameEntry]], ChunkEnd]:
    """The Dask task: the chunk's frame sets in order from the job's search state (after its warm-up), and
    where its search ended; never raises for a bad frame set (it is reported failed, the others go on)."""
    pin_threads()
    worker = worker_address()
    out: list[tuple[int, FrameEntry]] = []
    source = cached_source(job.take, job.calibration)
    processor = TakeProcessor(
        source, job.options, job.decision, Exporter(Path(job.out), formats=job.formats, atomic=True)
    )
    t0 = time.perf_counter()
    for item in processor.run_chunk(list(job.frames), catch=FAILURES, state=job.state):
        seconds = time.perf_counter() - t0
        if isinstance(item, FrameDone):
            entry = FrameEntry(
                status="done", worker=worker, seconds=seconds, report=item.report, files=item.files, start=job.state
            )
        else:
            # the client lists each failed frame set once at the end (a widened range computes it again)
            log.debug("frame %s failed: %s", item.number, item.error)
            entry = FrameEntry(status="failed", worker=worker, seconds=seconds, error=one_line(item.error))
        out.append((item.number, entry))
        del item  # its pictures and results: not held through the next frame set's depth
        t0 = time.perf_counter()
    return out, processor.chunk_end()


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
