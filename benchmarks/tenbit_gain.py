"""What a 10-bit take gains over an 8-bit one, on the simulator: the soft key's edge and the depth.

The same ideal scene (seed 3, soft edges with hair-like strands, still, no noise: quantisation is the only
difference) is recorded as UYVY and as Y210, through the installed ``rigctl``; on one camera (r1c1) it
scores the soft key's alpha against the truth's on the edge band (the alpha-matting measures of
rigctl.depth.matte_scores) and ``rigctl depth`` (preset best) against the true disparity. One run, both
formats; prints each figure for 8 and 10 bits and their ratio.

    python benchmarks/tenbit_gain.py [--noise SIGMA]   # --noise 1: the realistic sensor noise on top
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from rigctl.depth.grid import TakeGrid
from rigctl.depth.matte_scores import matte_scores
from rigctl.keying import Keyer
from rigctl.pfm import read_pfm
from rigctl.rig import load_rig

CAMERA = "r1c1"
RIGCTL = str(Path(sys.executable).with_name("rigctl"))


def record(folder: Path, pixel_format: str, noise: float) -> Path:
    data = load_rig("sim-3x3").to_dict()
    data["format"]["pixel_format"] = pixel_format
    rig = folder / f"{pixel_format}.yaml"
    rig.write_text(yaml.safe_dump(data, sort_keys=False))
    sim = ["ideal=true", "seed=3", "motion=false", "edges=soft", "deterministic=true", f"noise={noise:g}"]
    args = [RIGCTL, "record", str(rig), "--take", pixel_format, "--frames", "1", "--out", str(folder), "--force"]
    subprocess.run(args + [a for s in sim for a in ("--sim", s)], check=True, capture_output=True)
    return folder / pixel_format


def key_scores(take: Path) -> dict[str, float]:
    truth = read_pfm(take / "truth" / "alpha" / "000000" / f"{CAMERA}.pfm")
    rgb = TakeGrid(take).grid(0).images[CAMERA]
    return dict(matte_scores(Keyer().soft(rgb).alpha, truth))


def depth_scores(take: Path, out: Path) -> dict[str, float]:
    args = [RIGCTL, "depth", str(take), "--out", str(out), "--cameras", CAMERA, "--frames", "0", "--quiet"]
    subprocess.run(args, check=True, capture_output=True)
    report = json.loads((out / "report.json").read_text())
    first = next(iter(report["frames"].values()))
    return dict(first["cameras"][CAMERA]["against_truth"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise", type=float, default=0.0, help="sensor noise sigma, 8-bit grey levels")
    ns = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="rigctl-tenbit-"))
    try:
        rows = {}
        for pf in ("UYVY", "Y210"):
            take = record(folder, pf, ns.noise)
            rows[pf] = (key_scores(take), depth_scores(take, folder / f"depth-{pf}"))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    print(f"ideal seed-3 presenter, soft edges, still, noise {ns.noise:g}; {CAMERA}; 8-bit (UYVY) -> 10-bit (Y210):")
    (k8, d8), (k10, d10) = rows["UYVY"], rows["Y210"]
    print(f"  soft key on the edge band ({int(k8['band_pixels'])} px):")
    for m in ("sad_k", "mse", "gradient_k", "connectivity_k"):
        print(f"    {m:<15} {k8[m]:.4f} -> {k10[m]:.4f} ({k10[m] / max(k8[m], 1e-12):.3f}x)")
    print("  depth (preset best) against the true disparity:")
    for m in ("bad_0.1", "bad_0.2", "bad_0.5", "mae_px", "rms_px", "locking_pct"):
        a, b = d8.get(m), d10.get(m)
        if a is None or b is None:
            continue
        print(f"    {m:<15} {a:.4f} -> {b:.4f} ({b / max(a, 1e-12):.3f}x)")
    print(f"  (sums: {np.round([k8['sad_k'], k10['sad_k']], 4).tolist()})")


if __name__ == "__main__":
    main()
