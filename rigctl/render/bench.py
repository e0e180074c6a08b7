"""``rigctl bench render``: the time of a stereo pair from the four nearest cameras at a given size, with
the quality of the same renderer on the simulated presenter (leave-one-out of r1c1 and a view between
cameras against the simulator's own render there), measured in one run.

What the pair's time counts: for both eyes, the choice of the nearest cameras, the splat with its depth
test, crack closing, the background-side fill, the ring, and the per-pixel shade into 8-bit RGBA (what a
headset's compositor takes). Not counted, and reported on its own: the per-frame preparation of every
camera (8-bit RGBA, float32 disparity, the half-resolution samples: once per frame for both eyes, as a
GPU uploads textures), the kernels' first-call compile, float conversion and file writing."""

from __future__ import annotations

import logging
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypedDict

import cv2
import numpy as np

from rigctl.render import kernels
from rigctl.render.inputs import F32, FrameViews, View
from rigctl.render.score import Score, score
from rigctl.render.views import renderer_for
from rigctl.render.warp import Renderer, Source, prepare

log = logging.getLogger(__name__)

PAPER_PAIR_MS = 1000.0 / 90  # the paper's GPU renderer: one eye pair per 90 Hz headset frame
BUDGET_MS = 33.0  # a 30 fps preview on two CPU cores
IPD_M = 0.064
COUNTS = (
    "both eyes: nearest cameras, splat with depth test, crack closing, background-side fill, ring, "
    "per-pixel shade to 8-bit RGBA"
)


@dataclass
class RenderBenchData:
    """A simulated frame (colour, key, true disparity) and the simulator's view at ``truth_at``."""

    frame: FrameViews
    truth_at: tuple[float, float]
    truth_rgb: F32
    ignore: tuple[int, int, int, int] | None = None


class BenchQuality(TypedDict):
    take: str
    leave_one_out_r1c1: Score
    view: str
    view_against_truth: Score


class RenderBenchResult(TypedDict):
    """``rigctl bench render --json``."""

    stereo_pair_ms: float  # median of the warm pairs
    width: int
    height: int
    sources: list[str]  # the cameras either eye used
    taps: int
    repeats: int
    threads: int
    counts: str
    pair_ms_min: float
    pair_ms_max: float
    target_ms: float  # of the median pair: splat, closing, fill and ring, both eyes
    shade_ms: float  # of the median pair: the per-pixel shade, both eyes
    pair_cpu_ms: float  # CPU time per pair over all threads (a loaded machine stretches the wall time, not this)
    prepare_frame_ms: float  # every camera of a frame, into the last frame's images (not in the pair's time)
    prepare_frame_cold_ms: float  # the same, the first time in the process (fresh memory: page faults)
    first_call_s: float  # the kernels' first call in this process: compile, or load from Numba's cache
    compiled: bool  # False: the machine code came from the cache
    budget_ms: float
    ratio_to_budget: float
    paper_gpu_pair_ms: float
    ratio_to_paper: float
    quality: BenchQuality


def scaled(frame: FrameViews, width: int, height: int) -> list[tuple[str, tuple[float, float], F32, F32, F32]]:
    """(name, offset, RGB, alpha, disparity) of ``frame``'s cameras resampled to width x height (disparity
    scaled with the width)."""
    h0, w0 = frame.shape
    sx, sy = width / w0, height / h0
    out = []
    for v in frame.views.values():
        assert v.disparity is not None
        rgb = np.asarray(cv2.resize(v.rgb, (width, height), interpolation=cv2.INTER_LINEAR), np.float32)
        alpha = np.asarray(cv2.resize(v.alpha, (width, height), interpolation=cv2.INTER_LINEAR), np.float32)
        d = np.asarray(cv2.resize(v.disparity, (width, height), interpolation=cv2.INTER_NEAREST), np.float32)
        out.append((v.name, (v.offset[0], v.offset[1] * sy / sx), rgb, alpha, d * np.float32(sx)))
    return out


@dataclass
class PairTimes:
    total_ms: list[float]
    target_ms: list[float]
    shade_ms: list[float]
    names: list[str]
    cpu_ms: float = 0.0  # the process's CPU time per pair, all threads: what two free cores would share


def time_pair(ren: Renderer, u: float, v: float, half: float, repeats: int) -> PairTimes:
    """``repeats`` warm eye pairs (one more first, not counted, for caches and thread pools)."""
    t = PairTimes([], [], [], [])
    cpu0 = 0.0
    for i in range(repeats + 1):
        if i == 1:
            cpu0 = time.process_time()
        t0 = time.perf_counter()
        left, right = ren.render_pair((u - half, v), (u + half, v))
        t.total_ms.append((time.perf_counter() - t0) * 1e3)
        t.target_ms.append(left.target_ms + right.target_ms)
        t.shade_ms.append(left.shade_ms + right.shade_ms)
        t.names = sorted(set(left.sources) | set(right.sources))
    cpu_ms = (time.process_time() - cpu0) * 1e3 / repeats
    return PairTimes(t.total_ms[1:], t.target_ms[1:], t.shade_ms[1:], t.names, cpu_ms)


_FIRST: list[tuple[float, bool]] = []  # the first call's figures, kept for later runs in the process


def first_call(frame: FrameViews) -> tuple[float, bool]:
    """Seconds of the kernels' first call in this process on a small copy of the frame, and whether Numba
    compiled them (False: loaded from its cache). Later calls give the first one's figures again."""
    if _FIRST:
        return _FIRST[0]
    t0 = time.perf_counter()
    ren = Renderer([prepare(*s) for s in scaled(frame, 64, 36)])
    ren.render(*frame.views["r1c1"].offset)
    seconds = time.perf_counter() - t0
    fns = (kernels.prepare_source, kernels.splat, kernels.close_and_fill, kernels.shade)
    _FIRST.append((seconds, any(sum(f.stats.cache_misses.values()) for f in fns)))
    return _FIRST[0]


def bench_render(
    data: RenderBenchData,
    size: tuple[int, int],
    repeats: int = 10,
    progress: Callable[[int, int, str], None] | None = None,
) -> RenderBenchResult:
    """``progress(stage, 4, what)`` between the stages (never inside a timed one)."""

    def stage(k: int, what: str) -> None:
        if progress:
            progress(k, 4, what)

    frame = data.frame
    stage(0, "first call (compiling the kernels)")
    first_s, compiled = first_call(frame)
    stage(1, "quality: leave-one-out and the simulator's view")
    ren = renderer_for(frame)
    centre = frame.views["r1c1"]
    loo = ren.render(*centre.offset, exclude=("r1c1",))
    loo_score = score(loo.rgba[..., :3], centre.rgb, centre.alpha, data.ignore)
    novel = ren.render(*frame.position(*data.truth_at))
    from rigctl.keying import Keyer

    truth_score = score(novel.rgba[..., :3], data.truth_rgb, Keyer().matte(data.truth_rgb), data.ignore)
    width, height = size
    stage(2, f"sources at {width}x{height}")
    inputs = scaled(frame, width, height)
    t0 = time.perf_counter()
    sources: list[Source] = [prepare(*s) for s in inputs]  # cold: the process's first frame of this size
    cold_ms = (time.perf_counter() - t0) * 1e3
    t0 = time.perf_counter()
    sources = [prepare(*s, into=old) for s, old in zip(inputs, sources, strict=True)]  # each later frame
    warm_ms = (time.perf_counter() - t0) * 1e3
    big = Renderer(sources)
    u, v = centre.offset
    half = IPD_M / frame.spacing / 2
    stage(3, f"{repeats} timed stereo pairs")
    t = time_pair(big, u, v, half, repeats)
    stage(4, "done")
    pair_ms = statistics.median(t.total_ms)
    i = t.total_ms.index(sorted(t.total_ms)[(len(t.total_ms) - 1) // 2])  # the (lower) median pair
    return {
        "stereo_pair_ms": round(pair_ms, 2),
        "width": width,
        "height": height,
        "sources": t.names,
        "taps": big.taps,
        "repeats": repeats,
        "threads": big.threads,
        "counts": COUNTS,
        "pair_ms_min": round(min(t.total_ms), 2),
        "pair_ms_max": round(max(t.total_ms), 2),
        "target_ms": round(t.target_ms[i], 2),
        "shade_ms": round(t.shade_ms[i], 2),
        "pair_cpu_ms": round(t.cpu_ms, 2),
        "prepare_frame_ms": round(warm_ms, 1),
        "prepare_frame_cold_ms": round(cold_ms, 1),
        "first_call_s": round(first_s, 2),
        "compiled": compiled,
        "budget_ms": BUDGET_MS,
        "ratio_to_budget": round(pair_ms / BUDGET_MS, 2),
        "paper_gpu_pair_ms": round(PAPER_PAIR_MS, 2),
        "ratio_to_paper": round(pair_ms / PAPER_PAIR_MS, 2),
        "quality": {
            "take": f"simulated presenter, ideal, {frame.shape[1]}x{frame.shape[0]}, true disparity",
            "leave_one_out_r1c1": loo_score,
            "view": f"{data.truth_at[0]:g},{data.truth_at[1]:g}",
            "view_against_truth": truth_score,
        },
    }


def format_bench(r: RenderBenchResult) -> str:
    q = r["quality"]
    loo, view = q["leave_one_out_r1c1"], q["view_against_truth"]
    return "\n".join(
        [
            f"stereo pair {r['width']}x{r['height']} from {len(r['sources'])} cameras ({' '.join(r['sources'])}), "
            f"{r['threads']} threads: {r['stereo_pair_ms']:.1f} ms median of {r['repeats']} warm pairs (min "
            f"{r['pair_ms_min']:.1f}, max {r['pair_ms_max']:.1f}); summed over both eyes: target disparity "
            f"{r['target_ms']:.1f} ms, shade {r['shade_ms']:.1f} ms; CPU time {r['pair_cpu_ms']:.1f} ms per pair "
            "over all threads",
            f"  counts {r['counts']}",
            f"budget {r['budget_ms']:.0f} ms (30 fps preview): ratio {r['ratio_to_budget']:.2f}x",
            f"the paper's GPU: {r['paper_gpu_pair_ms']:.1f} ms per pair at 90 fps: ratio {r['ratio_to_paper']:.2f}x",
            f"not counted: per-frame preparation of all cameras {r['prepare_frame_ms']:.1f} ms (once per frame, "
            f"both eyes; {r['prepare_frame_cold_ms']:.0f} ms for the process's first frame, fresh memory); "
            f"kernels' first call {r['first_call_s']:.2f} s "
            f"({'compiled' if r['compiled'] else 'loaded from the cache'})",
            f"quality on the {q['take']}:",
            f"  leave-one-out r1c1: PSNR {loo['psnr_db']:.2f} dB, SSIM {loo['ssim']:.4f}, "
            f"IV-PSNR {loo['ivpsnr_db']:.2f} dB",
            f"  view at {q['view']} against the simulator's view: PSNR {view['psnr_db']:.2f} dB, "
            f"SSIM {view['ssim']:.4f}, IV-PSNR {view['ivpsnr_db']:.2f} dB",
        ]
    )


def frame_from_arrays(
    views: dict[str, tuple[tuple[float, float], F32, F32, F32]], focal: float, spacing: float
) -> FrameViews:
    """A frame from {name: (offset, rgb, alpha, disparity)}."""
    return FrameViews(0, {n: View(n, o, rgb, a, d, True) for n, (o, rgb, a, d) in views.items()}, focal, spacing)
