"""``rigctl depth``: per camera and frame, disparity + depth written as EXR (NUKE layers), PFM, a colour-mapped
PNG preview (red near, blue far) and ``report.json`` (timings per stage, coverage, keyed share, levels left
out by the planned range, pixels where the range's bound was hit)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import Grid, TakeGrid, load_grid_folder
from rigctl.depth.key import Keyer
from rigctl.depth.metrics import score
from rigctl.depth.multibaseline import PRESETS, DepthResult, cross_check, estimate
from rigctl.errors import ParameterError
from rigctl.exr import write_exr
from rigctl.pfm import write_pfm

F32 = NDArray[np.float32]


@dataclass(frozen=True)
class DepthOptions:
    preset: str = "best"
    near_m: float | None = None
    far_m: float | None = None
    disparity_range: tuple[float, float] | None = None
    key: bool = True
    cameras: tuple[str, ...] | None = None
    margin_px: float = 2.0


def planned_range(grid: Grid, opt: DepthOptions) -> tuple[tuple[float, float], str]:
    """The disparity search range and where it came from: --near/--far (planner), the grid's own range, or
    the whole plausible range (0 to a quarter of the image width) when nothing is known."""
    if opt.disparity_range is not None:
        return opt.disparity_range, "given disparity range"
    if opt.near_m is not None:
        far = opt.far_m if opt.far_m is not None else math.inf
        if not (opt.near_m > 0 and far > opt.near_m):
            raise ParameterError(f"--near must be positive and below --far, got {opt.near_m} and {far}")
        hi = grid.focal_px * grid.spacing / opt.near_m - grid.doffs
        lo = grid.focal_px * grid.spacing / far - grid.doffs if math.isfinite(far) else -grid.doffs
        return (lo - opt.margin_px, hi + opt.margin_px), f"planned from near {opt.near_m} m, far {far} m"
    if grid.disparity_range is not None:
        return grid.disparity_range, "grid.yaml disparity_range_px"
    return unplanned_range(grid), "no plan: the whole plausible range"


def unplanned_range(grid: Grid) -> tuple[float, float]:
    return 0.0, float(grid.shape[1]) / 4


def _rel(grid: Grid, a: str, b: str) -> tuple[float, float]:
    return grid.offsets[b][0] - grid.offsets[a][0], grid.offsets[b][1] - grid.offsets[a][1]


def depth_grid(grid: Grid, opt: DepthOptions, progress: Callable[[str], None] | None = None) -> dict[str, DepthResult]:
    """Depth for the requested cameras of one grid, cross-checked between cameras when the preset asks."""
    if opt.preset not in PRESETS:
        raise ParameterError(f"unknown preset {opt.preset!r} (presets: {', '.join(PRESETS)})")
    preset = PRESETS[opt.preset]
    cameras = list(opt.cameras) if opt.cameras else grid.names
    unknown = [c for c in cameras if c not in grid.names]
    if unknown:
        raise ParameterError(f"no camera {', '.join(unknown)} in the grid (it has {', '.join(grid.names)})")
    d_range, _ = planned_range(grid, opt)
    keyer = Keyer() if opt.key else None
    out = {}
    for cam in cameras:
        if progress:
            progress(cam)
        out[cam] = estimate(grid, cam, d_range, preset, keyer)
    if preset.cross_check and len(out) > 1:
        for cam, res in out.items():
            t0 = time.perf_counter()
            others = [c for c in out if c != cam]
            nearest = min(others, key=lambda c: math.hypot(*_rel(grid, cam, c)))
            # a point where two cameras disagree is not trusted (confidence 0); it is not replaced, because
            # either camera may be the one that is wrong there
            bad = cross_check(res, out[nearest], _rel(grid, cam, nearest)) & (res.matte > 0)
            res.confidence[bad] = 0.0
            res.stats["cross_check_with"] = nearest
            res.stats["cross_check_failed_pixels"] = int(bad.sum())
            res.stats["cross_check_s"] = time.perf_counter() - t0
    return out


def colour_preview(disparity: F32, d_range: tuple[float, float]) -> NDArray[np.uint8]:
    """Red near, blue far (as in the paper); black where there is no estimate."""
    lo, hi = d_range
    valid = np.isfinite(disparity)
    t = np.zeros(disparity.shape, np.float32)
    if hi > lo:
        t = np.clip((np.where(valid, disparity, lo) - lo) / (hi - lo), 0, 1)
    img = cv2.applyColorMap((t * 255).astype(np.uint8), cv2.COLORMAP_JET)  # high disparity (near) = red
    img[~valid] = 0
    return np.asarray(img)


def write_outputs(
    folder: Path, name: str, grid: Grid, res: DepthResult, d_range: tuple[float, float], formats: tuple[str, ...]
) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    d = res.disparity
    if "pfm" in formats:
        write_pfm(folder / f"{name}.pfm", d)
    if "png" in formats:
        cv2.imwrite(str(folder / f"{name}.png"), colour_preview(d, d_range))
    if "exr" in formats:
        z = grid.depth(d)
        inv_z = np.where(np.isfinite(z) & (z > 0), 1.0 / z, 0.0).astype(np.float32)
        fin = np.where(np.isfinite(d), d, 0.0).astype(np.float32)
        channels: dict[str, F32] = {"RGB": grid.images[name], "depth.Z": inv_z, "confidence.Y": res.confidence}
        ox, oy = grid.offsets[name]
        row = [n for n in grid.names if abs(grid.offsets[n][1] - oy) < 0.25 and n != name]
        if any(grid.offsets[n][0] < ox for n in row):
            channels["disparityL.x"] = fin  # the point is d further right in the left neighbour
            channels["disparityL.y"] = np.zeros_like(fin)
        if any(grid.offsets[n][0] > ox for n in row):
            channels["disparityR.x"] = -fin
            channels["disparityR.y"] = np.zeros_like(fin)
        col = [n for n in grid.names if abs(grid.offsets[n][0] - ox) < 0.25 and n != name]
        if col:
            ratio = min(abs(grid.offsets[n][1] - oy) for n in col)
            channels["disparityV.y"] = (-fin * ratio).astype(np.float32)  # shift to the camera below
        attrs = {
            "rigctl.camera": name,
            "rigctl.focal_px": f"{grid.focal_px:.6f}",
            "rigctl.spacing_x": f"{grid.spacing:.6f}",
            "rigctl.offset": f"{ox:.6f} {oy:.6f}",
            "rigctl.disparity": "pixels of the horizontal spacing; depth.Z holds 1/Z",
        }
        write_exr(folder / f"{name}.exr", channels, attrs)


def run_depth(
    source: Path,
    out: Path,
    opt: DepthOptions,
    frames: list[int] | None = None,
    formats: tuple[str, ...] = ("exr", "pfm", "png"),
    progress: Callable[[float, str], None] | None = None,
) -> dict[str, Any]:
    """Depth for a rectified take or a grid folder; writes outputs and ``report.json``; returns the report."""
    t_start = time.perf_counter()
    if (source / "take.yaml").exists():
        take = TakeGrid(source)
        numbers = take.frame_numbers()
        if frames is not None:
            missing = [f for f in frames if f not in numbers]
            if missing:
                raise ParameterError(f"{source}: frame set(s) {missing} are not complete frame sets of the take")
            numbers = frames
        if not numbers:
            raise ParameterError(f"{source}: the take has no complete frame set")

        def load(n: int) -> Grid:
            return take.grid(n)

        def folder(n: int) -> Path:
            return out / f"{n:06d}"
    elif (source / "grid.yaml").exists():
        numbers = [0]
        grid0 = load_grid_folder(source)

        def load(n: int) -> Grid:
            return grid0

        def folder(n: int) -> Path:
            return out
    else:
        raise ParameterError(f"{source}: not a take (take.yaml) or a grid folder (grid.yaml)")
    report: dict[str, Any] = {"source": str(source), "preset": opt.preset, "frames": {}}
    total = len(numbers)
    for i, n in enumerate(numbers):
        t0 = time.perf_counter()
        grid = load(n)
        t_load = time.perf_counter() - t0
        d_range, why = planned_range(grid, opt)
        full = unplanned_range(grid)
        cams = list(opt.cameras) if opt.cameras else grid.names

        def step(cam: str, i: int = i, n: int = n, cams: list[str] = cams) -> None:
            if progress:
                progress((i + cams.index(cam) / len(cams)) / total, f"frame {n} camera {cam}")

        results = depth_grid(grid, opt, step)
        if not any(np.isfinite(r.disparity).any() for r in results.values()):
            notes = sorted({str(r.stats.get("note", "no camera found a match")) for r in results.values()})
            raise ParameterError(f"{source}: frame {n}: no depth could be estimated: {'; '.join(notes)}")
        t0 = time.perf_counter()
        for cam, res in results.items():
            write_outputs(folder(n), cam, grid, res, d_range, formats)
        t_write = time.perf_counter() - t0
        per_cam = {}
        for cam, res in results.items():
            st = dict(res.stats)
            truth = grid.truth.get(cam) if grid.truth else None
            if truth is not None:
                st["against_truth"] = score(res.disparity, truth, np.isfinite(truth))
            per_cam[cam] = st
        levels_planned = d_range[1] - d_range[0]
        report["frames"][str(n)] = {
            "disparity_range_px": list(d_range),
            "range_source": why,
            "levels_skipped_by_plan": max(0.0, (full[1] - full[0]) - levels_planned),
            "keyed_background_share": float(np.mean([r.stats["keyed_background_share"] for r in results.values()])),
            "bound_hit_pixels": int(sum(r.stats.get("bound_hit_pixels", 0) for r in results.values())),
            "cameras": per_cam,
            "timings_s": {
                "load": t_load,
                "depth": float(sum(r.stats.get("seconds", 0.0) for r in results.values())),
                "write": t_write,
            },
        }
    report["seconds"] = time.perf_counter() - t_start
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").write_text(json.dumps(report, indent=1, default=float))
    if progress:
        progress(1.0, "done")
    return report
