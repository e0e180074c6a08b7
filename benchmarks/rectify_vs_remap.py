"""Rectifying a frame set against a bare ``cv2.remap`` of the same images with the same tables.

The rectifier builds its tables once per calibration (or loads them from the cache); per frame it only
remaps. This prints the median time per frame set of both, measured interleaved in one run, and their
ratio (the bar: at most 1.1). Also printed, for context: building the tables, and decoding captured UYVY
to 8-bit colour (which ``rigctl rectify`` does before remapping and the ratio leaves out).

    python benchmarks/rectify_vs_remap.py [RIG] [--repeats N]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from rigctl.simulators.array import SimArray
from rigctl.simulators.settings import SimSettings

from rigctl.pixfmt import from_rgb, uyvy_to_rgb
from rigctl.rectification.rectify import Rectifier
from rigctl.rig import load_rig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rig", nargs="?", default="sim-3x3")
    parser.add_argument("--repeats", type=int, default=30)
    ns = parser.parse_args()
    rig = load_rig(ns.rig)
    cv2.setNumThreads(2)
    arr = SimArray(rig, SimSettings(motion=False))
    calib = arr.calibration
    raw = arr.frames(0)
    t0 = time.perf_counter()
    images = {}
    for i, name in enumerate(arr.names):
        images[name] = np.ascontiguousarray(
            from_rgb(uyvy_to_rgb(raw[i]), "BGR3").reshape(rig.height_px, rig.width_px, 3)
        )
    decode = (time.perf_counter() - t0) / len(arr.names)
    with tempfile.TemporaryDirectory() as cache:
        t0 = time.perf_counter()
        rect = Rectifier(calib, cache=Path(cache))
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        Rectifier(calib, cache=Path(cache))
        cached = time.perf_counter() - t0
    maps = rect.maps
    ours, bare = [], []
    for _ in range(ns.repeats):
        t0 = time.perf_counter()
        rect.frame_set(images)
        ours.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        for name, img in images.items():
            cv2.remap(img, maps[name][0], maps[name][1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        bare.append(time.perf_counter() - t0)
    o, b = statistics.median(ours), statistics.median(bare)
    print(f"rig {rig.name}: {len(arr.names)} cameras, {rig.width_px}x{rig.height_px}, 8-bit BGR, {ns.repeats} repeats")
    print(f"tables: built in {build * 1e3:.0f} ms, loaded from cache in {cached * 1e3:.0f} ms (once per calibration)")
    print(f"rectify frame set {o * 1e3:.2f} ms; bare cv2.remap {b * 1e3:.2f} ms; ratio {o / b:.3f} (bar: <= 1.1)")
    print(f"for context: UYVY -> BGR decode {decode * 1e3:.1f} ms per image before remapping")


if __name__ == "__main__":
    main()
