"""rigctl view's frame time in a real headless Chromium: eye pairs (IPD 64 mm around the centre) rendered by the
page's WebGL2 shaders at the take's size (default 1920x1080), timed to the GPU's end of work, and which GL
implementation ran (software SwiftShader on a machine without a GPU); then playback of a 25-frame take at
480x270 (frame sets shown, seconds, waits for the server). Optionally a screenshot of the page for the README.

    python benchmarks/view_browser.py [--size 1920x1080] [--repeats 20] [--screenshot docs/viewer.png]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from rigctl.cli.render import size
from rigctl.viewer.browser import FLAGS, Probe, chromium, done_info
from rigctl.viewer.bundle import Bundles
from rigctl.viewer.server import ViewerServer

REPO = Path(__file__).resolve().parents[1]


def record(out: Path, wh: tuple[int, int], frames: int, *sim: str) -> Path:
    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", f"width_px: {wh[0]}").replace("height_px: 540", f"height_px: {wh[1]}")
    out.mkdir(parents=True, exist_ok=True)
    (out / "rig.yaml").write_text(rig)
    extra = [a for s in ("ideal=true", "deterministic=true", *sim) for a in ("--sim", s)]
    subprocess.run(
        ["rigctl", "record", str(out / "rig.yaml"), "--take", "t", "--frames", str(frames), "--out", str(out),
         *extra, "--force"], check=True, capture_output=True,
    )  # fmt: skip
    return out / "t"


def served(take: Path) -> ViewerServer:
    srv = ViewerServer(Bundles(take, take / "truth" / "disparity"), accept_results=True)
    srv.start()
    return srv


def pairs(take: Path, repeats: int) -> None:
    srv = served(take)
    try:
        with Probe(srv, probe="bench", repeats=str(repeats), ipd="64") as probe:
            got = probe.collect(timeout=900)
    finally:
        srv.shutdown()
        srv.server_close()
    bench = json.loads(got["bench"])
    ms = bench["pair_ms"]
    print(f"GL implementation: {done_info(got)['gl']}")
    print(
        f"eye pair {bench['width']}x{bench['height']} (two views, four sources each): "
        f"median {statistics.median(ms):.1f} ms, min {min(ms):.1f}, max {max(ms):.1f} over {len(ms)} pairs"
    )
    print("  per pair, pass by pass: " + ", ".join(f"{k} {v:.1f} ms" for k, v in bench["passes"].items()))
    print("  budget 33 ms per pair (30 fps preview); the paper's GPU renderer 11.1 ms per pair (90 fps)")


def playback(take: Path) -> None:
    srv = served(take)
    try:
        with Probe(srv, probe="play") as probe:
            played = json.loads(probe.collect(timeout=900)["play"])
    finally:
        srv.shutdown()
        srv.server_close()
    shown = played["shown"]
    seconds = (shown[-1]["t"] - shown[0]["t"]) / 1000
    print(
        f"playback 480x270, 25 frame sets (1.00 s at 25 fps): {len(shown)} shown in {seconds:.2f} s "
        f"({len(shown) / max(seconds, 1e-9):.1f} frame sets/s), {played['stalls']} waits for the server's bundles"
    )


def screenshot(take: Path, out: Path) -> None:
    srv = served(take)
    try:
        with tempfile.TemporaryDirectory() as profile:
            flags = [f for f in FLAGS if not f.startswith(("--remote-debugging", "--window-size"))]
            subprocess.run(
                [chromium(), *flags, f"--user-data-dir={profile}", "--window-size=1180,740",
                 "--virtual-time-budget=60000", "--run-all-compositor-stages-before-draw",
                 f"--screenshot={out.resolve()}", srv.url],
                check=True, capture_output=True, timeout=300,
            )  # fmt: skip
    finally:
        srv.shutdown()
        srv.server_close()
    print(f"wrote {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=size, default=(1920, 1080))
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--screenshot", type=Path, help="write a PNG of the page (960x540 take) here")
    parser.add_argument("--pairs-only", action="store_true", help="only the eye pairs")
    ns = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        big = record(Path(tmp) / "big", ns.size, 1, "motion=false")
        print(f"recorded the {ns.size[0]}x{ns.size[1]} take in {time.perf_counter() - t0:.1f} s")
        pairs(big, ns.repeats)
        if ns.pairs_only:
            return
        small = record(Path(tmp) / "small", (480, 270), 25, "motion_ramp_s=0")
        playback(small)
        if ns.screenshot:
            screenshot(record(Path(tmp) / "shot", (960, 540), 1, "motion=false"), ns.screenshot)


if __name__ == "__main__":
    main()
