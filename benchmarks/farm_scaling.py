"""Frames per second of ``rigctl process`` on a local Dask cluster of 1 and of 2 worker processes, measured in one
run on the same simulated take, and the scaling efficiency (2-worker rate / twice the 1-worker rate). The rate
counts from the first task submitted to the last result (cluster start-up excluded); both runs also check
their outputs are byte-identical.

    python benchmarks/farm_scaling.py [--size 480x270] [--frames 8] [--preset fast] [--workers 1,2]
"""

from __future__ import annotations

import argparse
import filecmp
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from rigctl.depth.run import DepthOptions
from rigctl.farm.run import FarmOptions, process_take

REPO = Path(__file__).resolve().parents[1]


def record(folder: Path, size: str, frames: int) -> Path:
    """An ideal simulated take (already rectified) of the given size, through the real recorder."""
    w, h = size.lower().split("x")
    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", f"width_px: {w}").replace("height_px: 540", f"height_px: {h}")
    (folder / "rig.yaml").write_text(rig)
    rigctl = str(Path(sys.executable).with_name("rigctl"))
    argv = [rigctl, "record", str(folder / "rig.yaml"), "--take", "bench", "--frames", str(frames)]
    sim = ["--sim", "ideal=true", "--sim", "deterministic=true"]  # every frame, the same bytes on any machine
    subprocess.run([*argv, "--out", str(folder), *sim, "--force"], check=True, capture_output=True)
    return folder / "bench"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="480x270")
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--preset", default="fast")
    parser.add_argument("--workers", default="1,2")
    ns = parser.parse_args()
    os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "warning")
    counts = [int(v) for v in ns.workers.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        take = record(Path(tmp), ns.size, ns.frames)
        rates = {}
        for n in counts:
            out = Path(tmp) / f"out{n}"
            s = process_take(FarmOptions(take, out, DepthOptions(preset=ns.preset, chunk=2), workers=n))
            assert s.failed == 0, s.failed_frames
            rates[n] = s.frames_per_second
            print(
                f"{n} worker(s): {s.computed} frame sets of {ns.size} in {s.compute_seconds:.1f} s, "
                f"{rates[n]:.3f} frames/s"
            )
        ref = Path(tmp) / f"out{counts[0]}" / "depth"
        for n in counts[1:]:
            other = Path(tmp) / f"out{n}" / "depth"
            for folder in sorted(ref.iterdir()):
                names = [p.name for p in folder.iterdir()]
                _, bad, err = filecmp.cmpfiles(folder, other / folder.name, names, shallow=False)
                assert not bad and not err, (folder.name, bad, err)
        base = counts[0]
        for n in counts[1:]:
            eff = rates[n] / (rates[base] * n / base)
            print(f"{n} workers against {base}: speed-up {rates[n] / rates[base]:.2f}x, efficiency {eff:.0%}")
        print(f"outputs byte-identical across worker counts; cores on this machine: {os.cpu_count()}")


if __name__ == "__main__":
    main()
