"""Calibration error against run time: 10, 20, 40 and 80 board views of a simulated ChArUco take.

Records one 80-pose take of the simulated 3x3 rig (realistic mounting errors, distortion, noise), detects
corners once, then calibrates on the first N poses for each N and prints, in one table: RMS, the
cross-validation disagreement (two halves, px), the worst camera's error against the truth (centre mm,
rotation and ray direction in degrees), and the seconds each calibration took (solve, held-out check and
cross-validation; detection is listed separately because it is shared).

    OPENBLAS_NUM_THREADS=1 python benchmarks/calibration_views.py [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from rigctl.board import BoardSpec
from rigctl.calib import metrics
from rigctl.calib.detect import detect
from rigctl.calib.inputs import load_views
from rigctl.calib.solve import solve
from rigctl.calibration_model import load_calibration


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--counts", default="10,20,40,80")
    ns = parser.parse_args()
    counts = [int(c) for c in ns.counts.split(",")]
    top = max(counts)
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(sys.executable).with_name("rigctl")
        t0 = time.perf_counter()
        subprocess.run(
            [
                str(exe),
                "record",
                "--take",
                "board",
                "--scene",
                "charuco",
                "--frames",
                str(top),
                "--out",
                tmp,
                "--sim",
                f"board_poses={top}",
                "--sim",
                "deterministic=true",  # every pose recorded, on a busy machine too
            ],
            check=True,
            capture_output=True,
        )
        t_record = time.perf_counter() - t0
        take = Path(tmp) / "board"
        truth = load_calibration(take / "truth" / "calibration.yaml")
        views = load_views(take)
        t0 = time.perf_counter()
        obs = detect(views, BoardSpec())
        t_detect = time.perf_counter() - t0
    points = BoardSpec().corners_m()
    names, sizes = views.names, [views.image_size] * len(views.names)
    rows = []
    for n in counts:
        frames = list(range(n))
        sub = obs.subset(np.isin(obs.frame, frames))
        t0 = time.perf_counter()
        fit = solve(points, sub, sizes, names)
        t_solve = time.perf_counter() - t0
        cal = metrics.to_rig(fit.solution, names, sizes, "sim-3x3")
        t0 = time.perf_counter()
        halves = [frames[0::2], frames[1::2]]
        try:
            a, b = (
                metrics.to_rig(
                    solve(points, obs.subset(np.isin(obs.frame, h)), sizes, names).solution, names, sizes, ""
                )
                for h in halves
            )
            cross = max(metrics.cross_validate(a, b, (1.8, 3.2)).values())
        except Exception as exc:  # a half too small to calibrate is itself a result
            cross = float("nan")
            print(f"  {n} views: cross-validation failed: {exc}", file=sys.stderr)
        t_cross = time.perf_counter() - t0
        err = metrics.compare_to_truth(cal, truth)
        rows.append(
            {
                "views": n,
                "rms_px": fit.solution.rms,
                "cross_validation_px": cross,
                "centre_mm": max(e["centre_mm"] for e in err.values()),
                "rotation_deg": max(e["rotation_deg"] for e in err.values()),
                "ray_deg": max(e["ray_deg"] for e in err.values()),
                "solve_s": t_solve,
                "cross_validation_s": t_cross,
            }
        )
    if ns.json:
        print(json.dumps({"record_s": t_record, "detect_s": t_detect, "rows": rows}))
        return
    print(f"simulated 3x3, 960x540; recorded {top} poses in {t_record:.0f} s, detected corners in {t_detect:.0f} s")
    print("views  RMS px   x-val px  centre mm  rot deg  ray deg  solve s  x-val s   (worst camera against truth)")
    for r in rows:
        print(
            f"{r['views']:5d}  {r['rms_px']:.4f}   {r['cross_validation_px']:.3f}     {r['centre_mm']:.3f}      "
            f"{r['rotation_deg']:.4f}   {r['ray_deg']:.4f}   {r['solve_s']:.2f}     {r['cross_validation_s']:.2f}"
        )


if __name__ == "__main__":
    main()
