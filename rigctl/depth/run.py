"""``rigctl depth``: per camera and frame, disparity + depth written as EXR (NUKE layers), PFM, a colour-mapped
PNG preview (red near, blue far) and ``report.json`` (timings per stage, coverage, keyed share, levels left
out by the planned range, pixels where the range's bound was hit)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.estimate import DepthResult, cross_check, estimate
from rigctl.depth.grid import Grid, SkippedFrameSet, TakeGrid, load_grid_folder
from rigctl.depth.key import Keyer
from rigctl.depth.measured_range import measured_range
from rigctl.depth.metrics import score
from rigctl.depth.presets import PRESETS
from rigctl.errors import ParameterError
from rigctl.exr import picture, picture_attributes, to_colour, write_exr
from rigctl.layout import output_path
from rigctl.pfm import write_pfm
from rigctl.take.manifest import DamagedFrame
from rigctl.timecode import Timecode

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
    """The disparity search range and where it came from: --near/--far (planner), the grid's own range, the
    range the images' feature matches show, or the whole plausible range (0 to a quarter of the image width)
    when nothing is known."""
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
    measured = measured_range(grid)
    if measured is not None:
        return measured, "no plan: measured from feature matches between the cameras"
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


@dataclass(frozen=True)
class Target:
    """Where one frame's outputs go (``rigctl.layout``) and what the pictures carry: rate and timecode."""

    out: Path
    layout: str
    frame: int
    fps: float | None = None
    timecode: Timecode | None = None
    flat: bool = False  # one picture (a grid folder): DIR/<camera>.<ext>
    colour: str = "rec709"  # rigctl.exr.COLOURS

    def path(self, camera: str, ext: str) -> Path:
        p = self.out / f"{camera}{ext}" if self.flat else output_path(self.out, self.layout, self.frame, camera, ext)
        p.parent.mkdir(parents=True, exist_ok=True)
        return p


def write_outputs(
    target: Target, name: str, grid: Grid, res: DepthResult, d_range: tuple[float, float], formats: tuple[str, ...]
) -> None:
    d = res.disparity
    if "pfm" in formats:
        write_pfm(target.path(name, ".pfm"), d)
    if "png" in formats:
        cv2.imwrite(str(target.path(name, ".png")), colour_preview(d, d_range))
    if "exr" in formats:
        z = grid.depth(d)
        inv_z = np.where(np.isfinite(z) & (z > 0), 1.0 / z, 0.0).astype(np.float32)
        fin = np.where(np.isfinite(d), d, 0.0).astype(np.float32)
        # the picture scene-linear and premultiplied by the key matte, as NUKE and Unreal read it
        channels: dict[str, F32] = {**picture(grid.images[name], res.matte, target.colour), "depth.Z": inv_z}
        channels["confidence.Y"] = res.confidence
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
            **picture_attributes(target.fps, target.timecode, target.colour),
            "rigctl.camera": name,
            "rigctl.focal_px": f"{grid.focal_px:.6f}",
            "rigctl.spacing_x": f"{grid.spacing:.6f}",
            "rigctl.offset": f"{ox:.6f} {oy:.6f}",
            "rigctl.disparity": "pixels of the horizontal spacing; depth.Z holds 1/Z",
        }
        write_exr(target.path(name, ".exr"), channels, attrs)


@dataclass
class FrameDepth:
    """One frame set's depth: the range searched and why, what was left out, each camera's estimator
    statistics (with its score against the truth, when the take has one) and the time of each stage."""

    disparity_range_px: tuple[float, float]
    range_source: str
    levels_skipped_by_plan: float
    keyed_background_share: float
    bound_hit_pixels: int
    cameras: dict[str, dict[str, object]]
    load_s: float
    depth_s: float
    write_s: float

    def to_json(self) -> dict[str, object]:
        return {
            "disparity_range_px": list(self.disparity_range_px),
            "range_source": self.range_source,
            "levels_skipped_by_plan": self.levels_skipped_by_plan,
            "keyed_background_share": self.keyed_background_share,
            "bound_hit_pixels": self.bound_hit_pixels,
            "cameras": self.cameras,
            "timings_s": {"load": self.load_s, "depth": self.depth_s, "write": self.write_s},
        }


@dataclass
class DepthReport:
    """What ``rigctl depth`` did (``report.json`` is :meth:`to_json`)."""

    source: str
    preset: str
    frames: dict[str, FrameDepth] = field(default_factory=dict)
    damaged_skipped: list[DamagedFrame] = field(default_factory=list)
    seconds: float = 0.0

    def to_json(self) -> dict[str, object]:
        data: dict[str, object] = {
            "source": self.source,
            "preset": self.preset,
            "frames": {n: f.to_json() for n, f in self.frames.items()},
        }
        if self.damaged_skipped:
            data["damaged_skipped"] = [d.model_dump(exclude_none=True) for d in self.damaged_skipped]
        data["seconds"] = self.seconds
        return data


def run_depth(
    source: Path,
    out: Path,
    opt: DepthOptions,
    frames: list[int] | None = None,
    formats: tuple[str, ...] = ("exr", "pfm", "png"),
    progress: Callable[[float, str], None] | None = None,
    skip_damaged: bool = False,
    layout: str = "frames",
    colour: str = "rec709",
) -> DepthReport:
    """Depth for a rectified take or a grid folder; writes outputs (in ``layout``, see rigctl.layout) and
    ``report.json``; returns the report.

    A damaged frame of a take stops it (naming file and byte) unless ``skip_damaged``: then its frame set is
    left out and the damaged frames are listed in the report's ``damaged_skipped``."""
    t_start = time.perf_counter()
    output_path(out, layout, 0, "", "")  # an unknown layout is refused before any work
    to_colour(np.zeros((1, 3), np.float32), colour)  # and an unknown colour space
    take: TakeGrid | None = None
    if (source / "take.yaml").exists():
        take = TakeGrid(source, skip_damaged=skip_damaged)
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

        sets = {s.number: s for s in take.reader.frame_sets}

        def target(n: int) -> Target:
            return Target(out, layout, n, take.reader.fps, take.reader.set_timecode(sets[n]), colour=colour)
    elif (source / "grid.yaml").exists():
        numbers = [0]
        grid0 = load_grid_folder(source)

        def load(n: int) -> Grid:
            return grid0

        def target(n: int) -> Target:
            # a grid folder is one picture: the frames layout keeps its outputs in DIR itself, as before
            return Target(out, layout, n, flat=layout == "frames", colour=colour)
    else:
        raise ParameterError(f"{source}: not a take (take.yaml) or a grid folder (grid.yaml)")
    report = DepthReport(str(source), opt.preset)
    total = len(numbers)
    for i, n in enumerate(numbers):
        t0 = time.perf_counter()
        try:
            grid = load(n)
        except SkippedFrameSet:
            continue
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
            write_outputs(target(n), cam, grid, res, d_range, formats)
        t_write = time.perf_counter() - t0
        per_cam: dict[str, dict[str, object]] = {}
        for cam, res in results.items():
            st: dict[str, object] = dict(res.stats)
            truth = grid.truth.get(cam) if grid.truth else None
            if truth is not None:
                st["against_truth"] = score(res.disparity, truth, np.isfinite(truth))
            per_cam[cam] = st
        levels_planned = d_range[1] - d_range[0]
        report.frames[str(n)] = FrameDepth(
            d_range,
            why,
            max(0.0, (full[1] - full[0]) - levels_planned),
            float(np.mean([r.stats["keyed_background_share"] for r in results.values()])),
            int(sum(r.stats.get("bound_hit_pixels", 0) for r in results.values())),
            per_cam,
            t_load,
            float(sum(r.stats.get("seconds", 0.0) for r in results.values())),
            t_write,
        )
    if take is not None:
        report.damaged_skipped = list(take.reader.damaged)
    report.seconds = time.perf_counter() - t_start
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").write_text(json.dumps(report.to_json(), indent=1, default=float))
    if progress:
        progress(1.0, "done")
    return report
