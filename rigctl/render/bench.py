"""``rigctl bench render``: the time of a stereo pair from the four nearest cameras at a given size, with
the quality of the same renderer on the simulated presenter (leave-one-out of r1c1 and a view between
cameras against the simulator's own render there), measured in one run."""

from __future__ import annotations

import logging
import statistics
import time
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from rigctl.render.inputs import F32, Frame, View
from rigctl.render.score import score
from rigctl.render.views import renderer_for
from rigctl.render.warp import Renderer, prepare

log = logging.getLogger(__name__)

PAPER_PAIR_MS = 1000.0 / 90  # the paper's GPU renderer: one eye pair per 90 Hz headset frame
IPD_M = 0.064


@dataclass
class RenderBenchData:
    """A simulated frame (colour, key, true disparity) and the simulator's view at ``truth_at``."""

    frame: Frame
    truth_at: tuple[float, float]
    truth_rgb: F32
    ignore: tuple[int, int, int, int] | None = None


def scaled(frame: Frame, width: int, height: int) -> list[Any]:
    """Sources for ``frame`` resampled to width x height (disparity scaled with the width)."""
    h0, w0 = frame.shape
    sx, sy = width / w0, height / h0
    out = []
    for v in frame.views.values():
        assert v.disparity is not None
        rgb = np.asarray(cv2.resize(v.rgb, (width, height), interpolation=cv2.INTER_LINEAR), np.float32)
        alpha = np.asarray(cv2.resize(v.alpha, (width, height), interpolation=cv2.INTER_LINEAR), np.float32)
        d = cv2.resize(v.disparity, (width, height), interpolation=cv2.INTER_NEAREST) * np.float32(sx)
        out.append(prepare(v.name, (v.offset[0], v.offset[1] * sy / sx), rgb, alpha, d))
    return out


def time_pair(ren: Renderer, u: float, v: float, half: float, repeats: int) -> tuple[list[float], list[str]]:
    times, names = [], []
    for _ in range(repeats + 1):  # the first pair warms caches and thread pools: not counted
        t0 = time.perf_counter()
        left = ren.render(u - half, v)
        right = ren.render(u + half, v)
        times.append((time.perf_counter() - t0) * 1e3)
        names = sorted(set(left.sources) | set(right.sources))
    return times[1:], names


def bench_render(data: RenderBenchData, size: tuple[int, int], repeats: int = 10) -> dict[str, Any]:
    frame = data.frame
    ren = renderer_for(frame)
    centre = frame.views["r1c1"]
    loo = ren.render(*centre.offset, exclude=("r1c1",))
    loo_score = score(loo.rgba[..., :3], centre.rgb, centre.alpha, data.ignore)
    novel = ren.render(*frame.position(*data.truth_at))
    from rigctl.depth.key import Keyer

    truth_score = score(novel.rgba[..., :3], data.truth_rgb, Keyer().matte(data.truth_rgb), data.ignore)
    width, height = size
    t0 = time.perf_counter()
    big = Renderer(scaled(frame, width, height))
    prep_ms = (time.perf_counter() - t0) * 1e3
    u, v = centre.offset
    half = IPD_M / frame.spacing / 2
    times, names = time_pair(big, u, v, half, repeats)
    pair_ms = statistics.median(times)
    return {
        "stereo_pair_ms": round(pair_ms, 2),
        "width": width,
        "height": height,
        "sources": names,
        "taps": big.taps,
        "repeats": repeats,
        "pair_ms_min": round(min(times), 2),
        "pair_ms_max": round(max(times), 2),
        "prepare_frame_ms": round(prep_ms, 1),
        "budget_ms": 33.0,
        "paper_gpu_pair_ms": round(PAPER_PAIR_MS, 2),
        "ratio_to_paper": round(pair_ms / PAPER_PAIR_MS, 2),
        "quality": {
            "take": f"simulated presenter, ideal, {frame.shape[1]}x{frame.shape[0]}, true disparity",
            "leave_one_out_r1c1": loo_score,
            "view": f"{data.truth_at[0]:g},{data.truth_at[1]:g}",
            "view_against_truth": truth_score,
        },
    }


def format_bench(r: dict[str, Any]) -> str:
    q = r["quality"]
    return "\n".join(
        [
            f"stereo pair {r['width']}x{r['height']} from {len(r['sources'])} cameras ({' '.join(r['sources'])}): "
            f"{r['stereo_pair_ms']:.1f} ms median of {r['repeats']} (min {r['pair_ms_min']:.1f}, max "
            f"{r['pair_ms_max']:.1f}); budget {r['budget_ms']:.0f} ms",
            f"the paper's GPU: {r['paper_gpu_pair_ms']:.1f} ms per pair at 90 fps; ratio {r['ratio_to_paper']:.2f}x",
            f"per-frame source preparation (texture upload): {r['prepare_frame_ms']:.1f} ms",
            f"quality on the {q['take']}:",
            f"  leave-one-out r1c1: PSNR {q['leave_one_out_r1c1']['psnr_db']:.2f} dB, "
            f"SSIM {q['leave_one_out_r1c1']['ssim']:.4f}",
            f"  view at {q['view']} against the simulator's view: PSNR {q['view_against_truth']['psnr_db']:.2f} dB, "
            f"SSIM {q['view_against_truth']['ssim']:.4f}",
        ]
    )


def frame_from_arrays(
    views: dict[str, tuple[tuple[float, float], F32, F32, F32]], focal: float, spacing: float
) -> Frame:
    """A frame from {name: (offset, rgb, alpha, disparity)}."""
    return Frame(0, {n: View(n, o, rgb, a, d, True) for n, (o, rgb, a, d) in views.items()}, focal, spacing)
