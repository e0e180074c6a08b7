"""Error against run time on light-field-sized input: the stratified scenes at 512x512 (the size of a 4D
light-field benchmark's views), written as grid folders and read back through the grid-folder input, centre
camera, 15 px border left out. Every preset, and the default with its stages switched off, in one run.
Prints bad 0.1 / 0.2 / 0.5 px, MSE x 100, the pixel-locking figure and seconds, and the default's time per
camera at this size.

    python benchmarks/depth_lightfield.py [--size 512]
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from rigctl.depth.estimate import estimate
from rigctl.depth.grid import load_grid_folder
from rigctl.depth.metrics import score
from rigctl.depth.presets import PRESETS
from rigctl.depth.scenes import SCENES, write_grid_folder


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=512)
    ns = parser.parse_args()
    cv2.setNumThreads(2)
    settings = {p: PRESETS[p] for p in PRESETS}
    settings["best, no refinement"] = dataclasses.replace(PRESETS["best"], lk_iterations=0)
    settings["best, no pairs candidate"] = dataclasses.replace(PRESETS["best"], with_pairs=False)
    print(f"{'scene':<10} {'setting':<26} bad0.1 bad0.2 bad0.5 MSEx100 lock %  seconds")
    with tempfile.TemporaryDirectory() as tmp:
        for name, make in SCENES.items():
            grid = load_grid_folder(write_grid_folder(make((ns.size, ns.size)), Path(tmp) / name))
            made = make((ns.size, ns.size))
            assert made.truth is not None and grid.disparity_range is not None
            t = made.truth["r1c1"]
            mask = np.zeros(t.shape, bool)
            mask[15:-15, 15:-15] = True
            for label, preset in settings.items():
                t0 = time.perf_counter()
                d = estimate(grid, "r1c1", grid.disparity_range, preset, keyer=None).disparity
                dt = time.perf_counter() - t0
                s = score(d, t, mask)
                print(
                    f"{name:<10} {label:<26} {s['bad_0.1']:6.2f} {s['bad_0.2']:6.2f} {s['bad_0.5']:6.2f}"
                    f" {s['mse_x100'] or 0:7.2f} {s['locking_pct'] or 0:6.1f} {dt:8.2f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
