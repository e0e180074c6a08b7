"""What checking every frame's CRC-32 costs a reader: read alone, read + CRC, and read + CRC + conversion
to RGB (what ``take export``, ``rectify`` and ``depth`` do with each frame).

Writes a one-camera take of 1080p UYVY frames to a temporary folder (read back from the page cache, so the
disk's speed does not enter), reads every frame each way, and prints per-frame milliseconds (best of three
passes), zlib's CRC-32 throughput and the CRC's share of each path -- ratios measured in this one run.

    python benchmarks/frame_crc_cost.py [--frames 24] [--width 1920 --height 1080]
"""

from __future__ import annotations

import argparse
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

from rigctl.interfaces import Frame, FrameFlags
from rigctl.pixfmt import to_rgb
from rigctl.take.manifest import TAKE_SPEC, Manifest, write_manifest
from rigctl.take.reader import TakeReader
from rigctl.take.writer import CameraWriter


def make_take(folder: Path, frames: int, width: int, height: int) -> None:
    rng = np.random.default_rng(1)
    writer = CameraWriter("r0c0", folder / "cameras", 25.0, sync_interval_s=0)
    size = width * height * 2
    for i in range(frames):
        data = rng.integers(0, 256, size, dtype=np.uint8)
        writer.write(Frame("r0c0", i, i * 40_000_000, i * 40_000_000, FrameFlags(0), memoryview(data.data)))
    writer.close()
    write_manifest(
        folder,
        Manifest.model_validate(
            {
                "spec": TAKE_SPEC,
                "take": "bench",
                "status": "complete",
                "format": {
                    "width": width,
                    "height": height,
                    "pixel_format": "UYVY",
                    "fps": 25.0,
                    "bytes_per_frame": size,
                },
                "cameras": {
                    "r0c0": {"essence": "cameras/r0c0.essence", "index": "cameras/r0c0.index", "frames": frames}
                },
            }
        ),
    )


def best_ms(fn: object, reader: TakeReader) -> float:
    n = len(reader.index["r0c0"])
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for i in range(n):
            fn(reader, i)  # type: ignore[operator]
        best = min(best, (time.perf_counter() - t0) / n * 1e3)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    ns = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "take"
        make_take(folder, ns.frames, ns.width, ns.height)
        reader = TakeReader(folder)
        w, h = reader.width, reader.height
        read = best_ms(lambda r, i: r.frame_bytes("r0c0", i, verify=False), reader)
        checked = best_ms(lambda r, i: r.frame_bytes("r0c0", i, verify=True), reader)
        converted = best_ms(lambda r, i: to_rgb(r.frame_bytes("r0c0", i, verify=False), "UYVY", w, h), reader)
        both = best_ms(lambda r, i: to_rgb(r.frame_bytes("r0c0", i, verify=True), "UYVY", w, h), reader)
        data = reader.frame_bytes("r0c0", 0).tobytes()
        t0 = time.perf_counter()
        for _ in range(10):
            zlib.crc32(data)
        gbps = 10 * len(data) / (time.perf_counter() - t0) / 1e9
    mb = ns.width * ns.height * 2 / 1e6
    print(
        f"{ns.frames} frames of {ns.width}x{ns.height} UYVY ({mb:.1f} MB each), page cache; zlib CRC-32 {gbps:.2f} GB/s"
    )
    print(f"{'path':<32}{'ms/frame':>10}{'CRC share':>11}")
    print(f"{'read':<32}{read:>10.2f}")
    print(f"{'read + CRC':<32}{checked:>10.2f}{(checked - read) / checked:>11.0%}")
    print(f"{'read + RGB conversion':<32}{converted:>10.2f}")
    print(f"{'read + CRC + RGB conversion':<32}{both:>10.2f}{(both - converted) / both:>11.0%}")


if __name__ == "__main__":
    main()
