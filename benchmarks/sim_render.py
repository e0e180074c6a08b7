"""Simulated array: rendering and delivery time per frame set against the rig's frame period.

Distinct scene states are rendered once (ray casting, all nine cameras) and cached; every delivered
frame set then costs a copy, noise and the burnt-in id per camera. Real-time delivery needs the second
figure under the frame period; the first is paid once per distinct state, before streaming starts.

    python benchmarks/sim_render.py [RIG] [--states N]
"""

from __future__ import annotations

import argparse
import time

from rigctl.simulators.array import SimArray
from rigctl.simulators.camera import SimCamera
from rigctl.simulators.settings import SimSettings

from rigctl.rig import load_rig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rig", nargs="?", default="sim-3x3")
    parser.add_argument("--states", type=int, default=4, help="distinct presenter states to render")
    ns = parser.parse_args()
    rig = load_rig(ns.rig)
    period = 1.0 / rig.fps
    size = f"{rig.width_px}x{rig.height_px}"
    print(f"rig {rig.name}: {len(rig.cameras)} cameras, {size}, frame period {period * 1e3:.1f} ms")
    for label, settings in (
        ("presenter, realistic", SimSettings(motion_states=ns.states)),
        ("presenter, ideal", SimSettings(ideal=True, motion_states=ns.states)),
        ("charuco, realistic", SimSettings(scene="charuco", board_poses=ns.states)),
    ):
        arr = SimArray(rig, settings)
        t0 = time.perf_counter()
        arr.frames(0)
        setup = time.perf_counter() - t0  # rays, static background, textures
        t0 = time.perf_counter()
        for state in range(1, ns.states):
            arr.frames(state)
        render = (time.perf_counter() - t0) / max(ns.states - 1, 1)
        arr._noise  # noqa: B018
        cams = [SimCamera(n, arr) for n in arr.names]
        timings = [next(arr.timing(n)) for n in arr.names]
        buf = [memoryview(bytearray(arr.format.bytes_per_frame)) for _ in cams]
        reps = 25
        t0 = time.perf_counter()
        for _ in range(reps):
            for cam, timing, b in zip(cams, timings, buf, strict=True):
                cam._deliver(timing, 0, b)
        deliver = (time.perf_counter() - t0) / reps
        print(
            f"{label:<22} setup {setup:6.2f} s | render {render * 1e3:7.1f} ms/set = {render / period:5.1f} periods"
            f" | deliver {deliver * 1e3:5.2f} ms/set = {deliver / period:4.2f} periods"
        )
    print("delivery below 1 period means real-time streaming from the cache; rendering is done before start")


if __name__ == "__main__":
    main()
