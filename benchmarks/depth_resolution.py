"""Issue 30's accuracy at the rig's resolution: the realistic simulated presenter (seed 0, rectified with its
true calibration, no camera noise, as ``rigctl bench depth`` has it) rendered at each size, ``best`` on one
camera, bad thresholds scaled with the width (bad 1.0 at 960x540 is bad 4.0 at 3840x2160: the same error
in the scene), overall and on the band within 3 px (at 960x540, scaled) of a truth edge or of the
silhouette. ``--upscaled`` adds the 960x540 render resampled to each size (bilinear, truth by nearest), the
input ``rigctl bench depth --size`` times: it has no detail finer than the 960x540 pixel, so it is not the
same scene at that size.

    python benchmarks/depth_resolution.py [--sizes 960x540,1920x1080,3840x2160] [--upscaled] [--camera r1c1]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from rigctl.depth.bench import Dataset, preset_disparity
from rigctl.farm.membench import scaled
from rigctl.simulated_presenter import presenter

REPO = Path(__file__).resolve().parents[1]
BASE_WIDTH = 960


def rendered(size: tuple[int, int], folder: Path) -> Dataset:
    """The realistic presenter rendered at ``size`` by the simulated rig with only its format changed."""
    w, h = size
    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", f"width_px: {w}").replace("height_px: 540", f"height_px: {h}")
    path = folder / f"sim-{w}x{h}.yaml"
    path.write_text(rig)
    return presenter(False, str(path))


def upscaled(base: Dataset, size: tuple[int, int]) -> Dataset:
    grid, d_range = scaled(base.grid, base.d_range, *size)
    k = np.float32(size[0] / base.truth.shape[1])
    truth = np.asarray(cv2.resize(base.truth * k, size, interpolation=cv2.INTER_NEAREST), np.float32)
    return Dataset(base.name + ", upscaled", grid, base.camera, truth, d_range, base.key)


def edge_band(truth: np.ndarray, k: float) -> np.ndarray:
    """Pixels within 3 x ``k`` px of a step of more than ``k`` px in the truth, or of the silhouette."""
    have = np.isfinite(truth)
    t = np.where(have, truth, 0).astype(np.float32)
    step = np.maximum(np.abs(np.diff(t, axis=1, append=t[:, -1:])), np.abs(np.diff(t, axis=0, append=t[-1:])))
    rim = have & ~cv2.erode(have.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    r = max(1, round(3 * k))
    near = cv2.dilate(((step > k) & have | rim).astype(np.uint8), np.ones((2 * r + 1, 2 * r + 1), np.uint8))
    return np.asarray(near > 0) & have


def report(ds: Dataset, label: str) -> None:
    k = ds.truth.shape[1] / BASE_WIDTH
    t0, c0 = time.perf_counter(), time.process_time()
    d = preset_disparity(ds, "best")
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    have = np.isfinite(ds.truth)
    with np.errstate(invalid="ignore"):
        err = np.where(np.isfinite(d), np.abs(d - ds.truth), np.inf)
    edge = edge_band(ds.truth, k)

    def bad(x: float, where: np.ndarray) -> float:
        return float(np.mean(err[where] > x) * 100)

    print(
        f"{label:>24} x{k:g}: bad {0.5 * k:g} {bad(0.5 * k, have):6.3f} %  bad {k:g} {bad(k, have):6.3f} %  "
        f"bad {2 * k:g} {bad(2 * k, have):6.3f} %  (bad 1.0 {bad(1.0, have):6.3f} %)  "
        f"edge band ({edge.sum() / have.sum() * 100:.1f} %): bad {k:g} {bad(k, edge):6.2f} %, "
        f"rest {bad(k, have & ~edge):6.3f} %  {seconds:.0f} s, {cpu:.0f} CPU s, load {os.getloadavg()[0]:.1f}",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="960x540,1920x1080,3840x2160")
    parser.add_argument("--upscaled", action="store_true", help="also the 960x540 render resampled to each size")
    parser.add_argument("--camera", default="r1c1")
    ns = parser.parse_args()
    sizes = [(int(a), int(b)) for a, b in (s.lower().split("x") for s in ns.sizes.split(","))]
    print("realistic presenter, best, thresholds scaled by the width over 960 (xK)")
    with tempfile.TemporaryDirectory() as tmp:
        base = None
        for size in sizes:
            ds = rendered(size, Path(tmp))
            ds.camera = ns.camera
            ds.truth = ds.grid.truth[ns.camera] if ds.grid.truth else ds.truth
            report(ds, f"rendered {size[0]}x{size[1]}")
            if size == (BASE_WIDTH, 540):
                base = ds
            del ds
            if ns.upscaled and size[0] != BASE_WIDTH:
                base = base or rendered((BASE_WIDTH, 540), Path(tmp))
                report(upscaled(base, size), f"upscaled {size[0]}x{size[1]}")


if __name__ == "__main__":
    main()
