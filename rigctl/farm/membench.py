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
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import Grid
from rigctl.depth.options import DepthOptions
from rigctl.errors import ParameterError

T = TypeVar("T")

log = logging.getLogger(__name__)


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ParameterError(f"--size: expected WIDTHxHEIGHT such as 3840x2160, got {text!r}") from None
    if not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise ParameterError(f"--size: width and height must be 16..16384, got {text!r}")
    return w, h


def scaled(
    grid: Grid, d_range: tuple[float, float], width: int, height: int, eight_bit: bool = False
) -> tuple[Grid, tuple[float, float]]:
    """The grid resampled to width x height (focal length and disparities scale with the width): float RGB, or
    with ``eight_bit`` 8-bit BGR, as a rectified take's frames reach a worker (the speed bench's input)."""
    import cv2

    s = width / grid.shape[1]
    size = (width, height)
    images: dict[str, NDArray[Any]] = {}
    for n in grid.names:
        if eight_bit:
            images[n] = np.asarray(cv2.resize(grid.bgr8(n), size, interpolation=cv2.INTER_LINEAR), np.uint8)
        else:
            images[n] = np.asarray(cv2.resize(grid.images[n], size, interpolation=cv2.INTER_LINEAR), np.float32)
    out = Grid(list(grid.names), images, dict(grid.offsets), grid.focal_px * s, grid.spacing, grid.doffs * s)
    return out, (d_range[0] * s, d_range[1] * s)


def _peak_rss() -> int:
    """This process's peak resident memory (VmHWM) since it started or since :func:`_reset_peak`."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024  # kB on Linux


def phase_peak(run: Callable[[], T]) -> tuple[T, int]:
    """``run()`` and the peak resident memory while it ran (the peak counter restarted from the resident memory
    at its start: what was held before counts, what an earlier phase freed does not)."""
    _reset_peak()
    out = run()
    return out, _peak_rss()


def _reset_peak() -> None:
    """Start the peak again from the current resident memory (Linux: 5 > /proc/self/clear_refs)."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        log.warning("cannot reset the peak memory counter: the peak includes building the input")


# EstimateStats' <stage>_s, summed over cameras: the cost volume's and its second candidate's, then the rest of
# a frame set's depth (none of them within another, so what the depth spent outside them all is ``other``)
STAGES = (
    *("cost", "aggregation", "candidates", "refinement"),
    *("key", "sensor_fixed", "views_count", "temporal", "occlusion_order", "cross_check"),
)
WORK = ("integer_sweep", "band_sweep", "fractional_sweep", "pairs", "refine")  # EstimateStats' <stage>_pixel_levels
SGBM_RUNS = 3  # the reference pair is timed this many times, the median kept


def sgbm_reference(grid: Grid, d_range: tuple[float, float], threads: int) -> dict[str, Any]:
    """One OpenCV SGBM 3WAY pair (the centre camera and its horizontal neighbour) over the same range at the
    same size, with ``threads`` OpenCV threads: the yardstick of issue 24. Median of SGBM_RUNS runs."""
    import cv2

    from rigctl.depth.baselines import sgbm_pair
    from rigctl.depth.pairs import make_sgbm, neighbour

    ref = grid.names[len(grid.names) // 2]
    other = neighbour(grid, ref, 1, 0) or neighbour(grid, ref, -1, 0)
    scale = abs(grid.offsets[other][0] - grid.offsets[ref][0]) if other else 1.0
    levels = int(make_sgbm(d_range[0] * scale, d_range[1] * scale).getNumDisparities())
    grid.bgr8(ref), grid.bgr8(other or ref)  # the 8-bit images exist before the clock starts, as for a pair
    before = cv2.getNumThreads()
    cv2.setNumThreads(threads)
    try:
        times, cpu = [], []
        for _ in range(SGBM_RUNS):
            t0, c0 = time.perf_counter(), time.process_time()
            sgbm_pair(grid, ref, d_range)
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    finally:
        cv2.setNumThreads(before)
    return {
        "seconds": float(np.median(times)),
        "cpu_seconds": float(np.median(cpu)),
        "levels": levels,
        "threads": threads,
        "pair": [ref, other],
    }


def speed_summary(
    depth_s: float,
    write_s: float,
    stages_s: dict[str, float],
    sgbm_s: float,
    fps: float,
    workers: int,
    cpu: tuple[float, float] | None = None,
    write_cpu_s: float | None = None,
) -> dict[str, Any]:
    """The figures of issue 24 from measured times: the ratio of the frame set's depth (and of depth and
    writing) to one SGBM pair, the stages (what the depth spent outside the named ones is ``other``), the
    write share, and the real-time factor: compute seconds per second of footage at ``fps``, for one worker
    and for ``workers`` (chunks are independent: the farm divides it), and the hours a minute of footage takes.
    ``cpu``: the frame set's and the pair's CPU seconds (every thread), whose ratio a busy machine disturbs
    less than the elapsed times' (``ratio_cpu``, depth and write together). ``write_s`` is the write's elapsed
    time, all of which a run waits for (nothing overlaps the write); ``write_cpu_s``, with ``cpu``, gives the
    write's share of the frame set's CPU seconds (``write_cpu_share``), which the load of other work on the
    cores disturbs less."""
    if sgbm_s <= 0 or fps <= 0 or workers < 1:
        raise ParameterError(f"speed summary needs sgbm_s > 0, fps > 0, workers >= 1 (got {sgbm_s}, {fps}, {workers})")
    total = depth_s + write_s
    stages = {k: float(v) for k, v in stages_s.items()}
    stages["other"] = max(0.0, depth_s - sum(stages.values()))
    stages["write"] = write_s
    rtf = total * fps
    extra = {}
    if cpu is not None:
        if cpu[1] <= 0:
            raise ParameterError(f"speed summary needs the pair's CPU seconds > 0, got {cpu[1]}")
        extra["ratio_cpu"] = cpu[0] / cpu[1]
        if write_cpu_s is not None:
            if not 0 <= write_cpu_s <= cpu[0]:
                raise ParameterError(f"the write's {write_cpu_s} CPU seconds are not within the frame set's {cpu[0]}")
            extra["write_cpu_s"] = write_cpu_s
            extra["write_cpu_share"] = write_cpu_s / cpu[0] if cpu[0] > 0 else 0.0
    return {
        **extra,
        "ratio_depth": depth_s / sgbm_s,
        "ratio_total": total / sgbm_s,
        "stages_s": stages,
        "write_share": write_s / total if total > 0 else 0.0,
        "realtime_factor": {"1": rtf, str(workers): rtf / workers},
        "hours_per_minute": {"1": rtf * 60 / 3600, str(workers): rtf * 60 / 3600 / workers},
    }


def format_speed(r: dict[str, Any]) -> str:
    """The size bench as text: the frame set, the SGBM pair beside it, the ratio, stages, memory, real time."""
    w, h = r["size"]
    t, sm, sg = r["timings_s"], r["summary"], r["sgbm"]
    n = str(r["workers"])
    stages = ", ".join(f"{k} {v:.2f}" for k, v in sm["stages_s"].items())
    work = ", ".join(f"{k} {v:.3g}" for k, v in r["pixel_levels"].items())
    return "\n".join(
        [
            f"{w}x{h}, preset {r['preset']}, {len(r['cameras'])} cameras: {r['seconds']:.2f} s per frame set "
            f"(depth {t['depth']:.2f} s, write {t['write']:.2f} s: {'+'.join(map(str.upper, r.get('formats', [])))})",
            f"one OpenCV SGBM 3WAY pair, same size, {sg['levels']} levels, {sg['threads']} thread(s): "
            f"{sg['seconds']:.3f} s",
            f"ratio to the SGBM pair: depth {sm['ratio_depth']:.1f}x, depth + write {sm['ratio_total']:.1f}x"
            + (f"; in CPU seconds (depth + write) {sm['ratio_cpu']:.1f}x" if "ratio_cpu" in sm else ""),
            f"stages (s, summed over cameras): {stages}; write share {100 * sm['write_share']:.1f} %"
            + (
                f" of the elapsed time (nothing overlaps the write); {sm['write_cpu_s']:.2f} CPU s, "
                f"{100 * sm['write_cpu_share']:.1f} % of the CPU seconds"
                if "write_cpu_share" in sm
                else ""
            ),
            f"pixel-levels evaluated: {work}",
            f"peak memory {r['peak_rss_bytes'] / 2**30:.2f} GiB ("
            + (
                f"depth {r['peak_rss_depth_bytes'] / 2**30:.2f} GiB, write {r['peak_rss_write_bytes'] / 2**30:.2f} "
                "GiB; "
                if "peak_rss_write_bytes" in r
                else ""
            )
            + f"input images {r['input_bytes'] / 2**30:.2f} GiB, "
            f"{r['peak_rss_while_building_input_bytes'] / 2**30:.2f} GiB while the input was built)",
            (
                f"kernels loaded before the clock started, on a {warm['size'][0]}x{warm['size'][1]} frame set "
                f"({warm['seconds']:.1f} s); {warm['loaded_while_timed']} more loaded while timed"
                if (warm := r.get("warmup"))
                else "kernels not loaded beforehand: the times include compiling them"
            ),
            f"real-time factor at {r['fps']:g} fps: {sm['realtime_factor']['1']:.0f} s of compute per s of footage "
            f"on one worker, {sm['realtime_factor'][n]:.1f} on {n} workers "
            f"({sm['hours_per_minute']['1']:.1f} h and {sm['hours_per_minute'][n]:.2f} h per minute of footage)",
        ]
    )


def kernels_held() -> int:
    """How many compiled kernel signatures rigctl's Numba kernels hold in this process (each one compiled, or
    loaded from the cache, on its first call)."""
    import sys

    from numba.core.dispatcher import Dispatcher

    return sum(
        len(obj.signatures)
        for name, mod in list(sys.modules.items())
        if name.startswith("rigctl.") and mod is not None
        for obj in vars(mod).values()
        if isinstance(obj, Dispatcher)
    )


def warm_size(width: int, height: int) -> tuple[int, int]:
    """The warm-up frame set's size: a quarter of each side, not below 240x135 nor above the size itself."""
    return min(width, max(240, width // 4)), min(height, max(135, height // 4))


def _frame_set(grid: Grid, d_range: tuple[float, float], preset: str, cameras: tuple[str, ...] | None) -> Any:
    from rigctl.depth.export import Exporter
    from rigctl.depth.pipeline import TakeProcessor
    from rigctl.depth.sources import OneGrid

    opt = DepthOptions(preset=preset, disparity_range=d_range, cameras=cameras)
    with tempfile.TemporaryDirectory() as tmp:
        # one frame set through the pipeline as a worker runs it (TakeProcessor.process, in its two steps to
        # tell their peaks apart): depth, then staged and published by rename
        exporter = Exporter(Path(tmp), atomic=True)  # what rigctl depth and process write unless asked for more
        processor = TakeProcessor(OneGrid(grid), opt, exporter=exporter)
        computed, peak_depth = phase_peak(lambda: processor.computed(0))
        done, peak_write = phase_peak(computed.write)
        del computed
    return done, exporter, peak_depth, peak_write


def _measure(make: Callable[[], Any], width: int, height: int, preset: str, cameras: tuple[str, ...] | None) -> dict:
    from rigctl.farm.frame import pin_threads

    pin_threads()  # as on a worker
    ds = make()
    grid, d_range = scaled(ds.grid, ds.d_range, width, height, eight_bit=True)
    before = _peak_rss()
    # a small frame set first: the kernels are compiled on a machine's first run and loaded from Numba's cache
    # in every new process, which a worker pays once, not per frame set (a fresh checkout's first run: 91 s
    # instead of 54 at 1920x1080). What the timed frame set still had to load is reported
    ww, wh = warm_size(width, height)
    t0 = time.perf_counter()
    _frame_set(*scaled(ds.grid, ds.d_range, ww, wh, eight_bit=True), preset, cameras)
    held = kernels_held()
    warm: dict[str, Any] = {"size": [ww, wh], "seconds": time.perf_counter() - t0, "kernels": held}
    del ds
    gc.collect()
    t0, c0 = time.perf_counter(), time.process_time()
    done, exporter, peak_depth, peak_write = _frame_set(grid, d_range, preset, cameras)
    seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
    warm["loaded_while_timed"] = kernels_held() - held
    stats = done.report
    cams: list[dict[str, Any]] = [dict(c) for c in stats.cameras.values()]
    stages = {k: sum(float(c.get(f"{k}_s", 0.0)) for c in cams) for k in STAGES}
    work = {k: sum(int(c.get(f"{k}_pixel_levels", 0)) for c in cams) for k in WORK}
    import numba

    sgbm = sgbm_reference(grid, d_range, numba.get_num_threads())  # as many threads as our kernels use
    return {
        "size": [width, height],
        "preset": preset,
        "cameras": list(stats.cameras),
        "formats": list(exporter.formats),
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
        "timings_s": {
            "depth": stats.timings_s.depth,
            "write": stats.timings_s.write,
            "write_cpu": stats.timings_s.write_cpu,
        },
        "stages_s": stages,
        "pixel_levels": work,
        "sgbm": sgbm,
        "peak_rss_bytes": max(peak_depth, peak_write),
        "peak_rss_depth_bytes": peak_depth,
        "peak_rss_write_bytes": peak_write,
        "peak_rss_while_building_input_bytes": before,
        "input_bytes": int(sum(grid.bgr8(n).nbytes for n in grid.names)),  # as given: 8-bit BGR
        "warmup": warm,
    }


def measure_size(
    make: Callable[[], Any], width: int, height: int, preset: str = "best", cameras: tuple[str, ...] | None = None
) -> dict[str, Any]:
    """Run :func:`_measure` in a new process (``make`` builds the dataset there and must be picklable)."""
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(1) as pool:
        return dict(pool.apply(_measure, (make, width, height, preset, cameras)))
