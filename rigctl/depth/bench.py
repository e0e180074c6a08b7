"""``rigctl bench depth``: error against run time for every preset and for OpenCV baselines, measured in the
same run on the same grids and disparity ranges: the simulated presenter (ideal, and realistic: rectified
with its true calibration so the truth is exact) and Middlebury's Motorcycle pair shipped inside
scikit-image (a 1x2 grid). Metrics on pixels with ground truth (the subject only for the presenter)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.baselines import BASELINES
from rigctl.depth.grid import Grid, grid_from_arrays
from rigctl.depth.metrics import score
from rigctl.depth.options import DepthOptions
from rigctl.depth.presets import PRESETS
from rigctl.depth.scenes import SCENES, SPACING, seen_by_all, shifted
from rigctl.publish import publish_figure

# the Middlebury 2014 Motorcycle calibration (REFERENCE.md): quarter resolution of f, doffs as shipped
MOTORCYCLE = {"focal_px": 994.978, "spacing": 0.193001, "doffs": 31.086}


@dataclass
class Dataset:
    name: str
    grid: Grid
    camera: str
    truth: NDArray[np.float32]
    d_range: tuple[float, float]
    key: bool


def motorcycle() -> Dataset:
    from skimage import data

    left, right, disp = data.stereo_motorcycle()
    grid = grid_from_arrays(
        {"r0c0": np.asarray(left, np.float32) / 255.0, "r0c1": np.asarray(right, np.float32) / 255.0},
        MOTORCYCLE["focal_px"],
        MOTORCYCLE["spacing"],
        MOTORCYCLE["spacing"],
        MOTORCYCLE["doffs"],
    )
    truth = np.asarray(disp, np.float32)
    return Dataset("motorcycle (1x2)", grid, "r0c0", truth, (0.0, 64.0), key=False)


def stratified(size: tuple[int, int] = (256, 256), seed: int = 0) -> list[Dataset]:
    """The stratified light-field scenes (slanted and curved surfaces, thin bars, weak texture, fractional
    truth everywhere), centre camera of 3x3, a 15 px border left out as the light-field benchmark does."""
    out = []
    for name, make in SCENES.items():
        grid = make(size, seed)
        assert grid.truth is not None and grid.disparity_range is not None
        truth = grid.truth["r1c1"].copy()
        b = 15 if min(size) > 60 else 0
        if b:
            truth[:b], truth[-b:], truth[:, :b], truth[:, -b:] = np.inf, np.inf, np.inf, np.inf
        out.append(Dataset(f"stratified {name} (3x3)", grid, "r1c1", truth, grid.disparity_range, key=False))
    return out


def stratified_shifted(offset: int = 60, size: tuple[int, int] = (256, 256), seed: int = 0) -> list[Dataset]:
    """Each stratified scene twice from one rendering: as a light field sees it, and with every disparity grown
    by ``offset`` px per horizontal spacing, as parallel cameras (the rig's) see it (``scenes.shifted``: the
    same reference picture, the views cropped). Rendered large enough that the region every view sees at the
    offset is about ``size``; both are scored there only, so a gap between the two rows is the estimator's
    dependence on where the range lies."""
    out = []
    big = (size[0] + math.ceil(4 * offset * SPACING[1] / SPACING[0]), size[1] + 4 * offset)
    for name, make in SCENES.items():
        grid = make(big, seed)
        far = shifted(grid, "r1c1", offset)
        assert far.truth is not None
        region = seen_by_all(far, "r1c1", far.truth["r1c1"], margin=15)
        for s, g in ((0, shifted(grid, "r1c1", 0, offset)), (offset, far)):
            assert g.truth is not None and g.disparity_range is not None
            truth = np.where(region, g.truth["r1c1"], np.inf).astype(np.float32)
            out.append(Dataset(f"stratified {name} (3x3) +{s} px", g, "r1c1", truth, g.disparity_range, key=False))
    return out


def dataset_from_array(array: Any, name: str, camera: str = "r1c1") -> Dataset:
    """The first frame set of a simulated array as rendered (no camera noise), rectified with its true
    calibration, searched over the planned range."""
    from rigctl.depth.array_take import ArrayTake

    take = ArrayTake(array, 1, name, noise=False)
    grid = take.grid(0)
    assert grid.truth is not None
    return Dataset(name, grid, camera, grid.truth[camera], take.planned_range(), key=True)


@dataclass(frozen=True)
class BenchRow:
    """One method on one dataset: its scores (:func:`rigctl.depth.metrics.score`) and run time."""

    dataset: str
    method: str
    seconds: float
    scores: dict[str, float | None]

    def metric(self, key: str) -> float:
        """A score; a missing one (nothing estimated) as infinity, the worst."""
        value = self.scores[key]
        return math.inf if value is None else value

    def to_json(self) -> dict[str, object]:
        return {"dataset": self.dataset, "method": self.method, "seconds": self.seconds, **self.scores}


@dataclass
class DepthBenchResult:
    rows: list[BenchRow] = field(default_factory=list)
    datasets: list[str] = field(default_factory=list)
    repeats: int = 1

    def of(self, dataset: str) -> list[BenchRow]:
        return [r for r in self.rows if r.dataset == dataset]

    def to_json(self) -> dict[str, object]:
        return {"rows": [r.to_json() for r in self.rows], "datasets": self.datasets, "repeats": self.repeats}


@dataclass(frozen=True)
class Comparison:
    """A preset against the best OpenCV baseline of its dataset (on bad 1.0)."""

    dataset: str
    preset: str
    baseline: str
    bad1_improvement: float  # relative: 0.3 is 30 % fewer bad pixels
    time_ratio: float


def preset_disparity(ds: Dataset, preset: str) -> NDArray[np.float32]:
    """A preset on one dataset through the take-level pipeline, as rigctl depth runs it on one frame set: the
    dataset's range given, its camera alone, no temporal state (a still)."""
    from rigctl.depth.pipeline import TakeProcessor
    from rigctl.depth.sources import OneGrid

    opt = DepthOptions(preset, disparity_range=ds.d_range, key=ds.key, cameras=(ds.camera,), temporal=False)
    return TakeProcessor(OneGrid(ds.grid, ds.name), opt).depth(ds.grid)[ds.camera].disparity


def run_bench(
    datasets: list[Dataset],
    methods: list[str] | None = None,
    repeats: int = 1,
    progress: Callable[[int, int, str], None] | None = None,
) -> DepthBenchResult:
    """Every method on every dataset: metrics and seconds (the median of ``repeats`` runs)."""
    cv2.setNumThreads(2)
    names = methods or [*PRESETS, *BASELINES]
    rows = []
    total = len(datasets) * len(names)
    k = 0
    for ds in datasets:
        mask = np.isfinite(ds.truth)
        for m in names:
            if progress:
                progress(k, total, f"{ds.name}: {m}")
            k += 1
            if m in PRESETS and len(ds.grid.names) < 2:
                continue
            times = []
            disp = None
            for _ in range(repeats):
                t0 = time.perf_counter()
                if m in PRESETS:
                    disp = preset_disparity(ds, m)
                else:
                    disp = BASELINES[m](ds.grid, ds.camera, ds.d_range)
                times.append(time.perf_counter() - t0)
            assert disp is not None
            rows.append(BenchRow(ds.name, m, float(np.median(times)), score(disp, ds.truth, mask)))
    if progress:
        progress(total, total, "done")
    return DepthBenchResult(rows, [d.name for d in datasets], repeats)


def comparisons(result: DepthBenchResult) -> list[Comparison]:
    """Per dataset: the best OpenCV baseline on bad 1.0, and every preset against it (relative improvement,
    time ratio)."""
    out = []
    for ds in result.datasets:
        rows = result.of(ds)
        base = [r for r in rows if r.method in BASELINES]
        ours = [r for r in rows if r.method in PRESETS]
        if not base or not ours:
            continue
        best = min(base, key=lambda r: r.metric("bad_1.0"))
        b1 = best.metric("bad_1.0")
        for r in ours:
            out.append(
                Comparison(
                    ds,
                    r.method,
                    best.method,
                    (b1 - r.metric("bad_1.0")) / b1 if b1 else 0.0,
                    r.seconds / best.seconds if best.seconds else math.inf,
                )
            )
    return out


def better(rel: float) -> str:
    """A relative improvement as words: "31 % better" or "12 % worse"."""
    return f"{rel * 100:.0f} % better" if rel >= 0 else f"{-rel * 100:.0f} % worse"


def format_table(result: DepthBenchResult) -> str:
    lines = []
    for ds in result.datasets:
        lines.append(f"{ds}")
        lines.append(
            "  method            bad0.1 bad0.2 bad0.5 bad1.0 bad2.0  MAE px  RMS px  MSEx100 lock %  no est %"
            "  false fg %  missed %  seconds"
        )
        rows = result.of(ds)
        front = pareto(rows)
        for r in rows:
            sc = r.scores
            num = {k: "-" if sc.get(k) is None else f"{sc[k]:.3f}" for k in ("mae_px", "rms_px")}
            mse = "-" if sc.get("mse_x100") is None else f"{sc['mse_x100']:.2f}"
            lock = "-" if sc.get("locking_pct") is None else f"{sc['locking_pct']:.1f}"
            star = "*" if r.method in front else " "
            lines.append(
                f" {star}{r.method:<17} "
                + " ".join(f"{r.metric(f'bad_{x}'):6.2f}" for x in (0.1, 0.2, 0.5, 1.0, 2.0))
                + f" {num['mae_px']:>7} {num['rms_px']:>7} {mse:>8} {lock:>6}"
                f"  {r.metric('no_estimate_pct'):8.2f}  {r.metric('false_fg_pct'):10.3f}"
                f"  {r.metric('missed_fg_pct'):8.3f}  {r.seconds:7.3f}"
            )
    lines.append("* on the Pareto front of bad 0.2 against seconds (nothing is both faster and more accurate)")
    for c in comparisons(result):
        lines.append(
            f"{c.dataset}: {c.preset} vs {c.baseline}: bad 1.0 {better(c.bad1_improvement)}, "
            f"{c.time_ratio:.2f}x the time"
        )
    return "\n".join(lines)


def pareto(rows: list[BenchRow], key: str = "bad_0.2") -> set[str]:
    """Methods no other method beats on both ``key`` and seconds."""
    return {
        r.method
        for r in rows
        if not any(
            o is not r
            and o.metric(key) <= r.metric(key)
            and o.seconds <= r.seconds
            and (o.metric(key), o.seconds) != (r.metric(key), r.seconds)
            for o in rows
        )
    }


def plot(result: DepthBenchResult, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(result.datasets)
    fig, axes = plt.subplots(1, n, figsize=(4.6 * n, 3.8), squeeze=False)
    for ax, ds in zip(axes[0], result.datasets, strict=True):
        rows = result.of(ds)
        front = sorted((r for r in rows if r.method in pareto(rows)), key=lambda r: r.seconds)
        ax.plot([r.seconds for r in front], [r.metric("bad_0.2") for r in front], c="0.6", lw=1, zorder=0)
        for r in rows:
            ours = r.method in PRESETS
            bad = r.metric("bad_0.2")
            ax.scatter(r.seconds, bad, marker="o" if ours else "s", c="tab:red" if ours else "tab:blue")
            ax.annotate(r.method.removeprefix("opencv-"), (r.seconds, bad), fontsize=7)
        ax.set_xscale("log")
        ax.set_xlabel("seconds (one camera)")
        ax.set_ylabel("bad 0.2 px (%)")
        ax.set_title(ds, fontsize=9)
        ax.grid(alpha=0.3)
    fig.suptitle("error against run time: rigctl presets (red), OpenCV (blue), Pareto front (grey)", fontsize=9)
    fig.tight_layout()
    publish_figure(path, fig, 90)  # whole or absent, never a cut PNG
    plt.close(fig)
    return path
