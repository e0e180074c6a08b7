"""What leaving out costs and saves: depth for one camera of the simulated presenter with keying and the
planned disparity range, against the same run with keying off and the whole plausible range (0 to a quarter
of the image width), in one run. Prints seconds, the ratio, and the error of both against the truth.

    python benchmarks/depth_skip.py [--preset best] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from rigctl.depth.estimate import estimate
from rigctl.depth.metrics import score
from rigctl.depth.presets import PRESETS
from rigctl.depth.take_range import unplanned_range
from rigctl.keying import Keyer
from rigctl.simulated_presenter import presenter


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="best", choices=list(PRESETS))
    parser.add_argument("--repeats", type=int, default=3)
    ns = parser.parse_args()
    ds = presenter(ideal=False)
    mask = np.isfinite(ds.truth)
    full = unplanned_range(ds.grid.shape[1])
    runs = {"keyed, planned range": (Keyer(), ds.d_range), "no key, whole range": (None, full)}
    out = {}
    for label, (keyer, d_range) in runs.items():
        times = []
        res = None
        for _ in range(ns.repeats):
            t0 = time.perf_counter()
            res = estimate(ds.grid, ds.camera, d_range, PRESETS[ns.preset], keyer)
            times.append(time.perf_counter() - t0)
        assert res is not None
        out[label] = (statistics.median(times), score(res.disparity, ds.truth, mask), res.stats, d_range)
    print(f"{ds.name}, camera {ds.camera}, preset {ns.preset}, median of {ns.repeats}")
    for label, (sec, sc, st, d_range) in out.items():
        print(
            f"  {label:<22} {sec:6.2f} s  range {d_range[0]:.0f}..{d_range[1]:.0f} px ({st['levels']} levels), "
            f"searched {st['searched_share']:.0%} of the image, keyed out {st['keyed_background_share']:.0%}; "
            f"bad 1.0 {sc['bad_1.0']:.2f} %"
        )
    a, b = out["keyed, planned range"][0], out["no key, whole range"][0]
    print(f"time with keying and planning / without: {a / b:.2f} (saves {(1 - a / b) * 100:.0f} %)")


if __name__ == "__main__":
    main()
