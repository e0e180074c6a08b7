"""Recorder throughput: nine 1920x1080 UYVY streams to disk, against a plain sequential write.

Nine cameras deliver pre-rendered frames at a paced rate; the rate is raised step by step until the
recorder drops a frame, and the highest rate without a drop is the recorder's sustained rate. In the
same run a plain sequential write of the same number of bytes to the same disk (write, then fdatasync)
gives the disk's own speed. Prints both, their ratio (target >= 0.8) and the recorder's CPU time per
frame.

    python benchmarks/record_throughput.py [--dir DIR] [--seconds S]
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from rigctl.interfaces import CameraStatus, CaptureFormat, Frame, FrameFlags
from rigctl.recorder import Recorder, TakePlan
from rigctl.registry import DeviceSet
from rigctl.rig import load_rig, rig_from_dict

W, H = 1920, 1080


class PacedCamera:
    """Delivers pre-rendered frames at ``fps`` on a common clock (a stand-in for a capture card)."""

    def __init__(self, name: str, frames: list[bytes], fps: float, t0: int) -> None:
        self.name = name
        self.frames = frames
        self.period = round(1e9 / fps)
        self.t0 = t0
        self.seq = 0
        self.fmt = CaptureFormat(W, H, "UYVY", fps)

    def open(self) -> None: ...
    def configure(self, fmt: CaptureFormat) -> CaptureFormat:
        return self.fmt

    def start(self) -> None:
        self.seq = max(0, (time.monotonic_ns() - self.t0) // self.period + 1)

    def read(self, timeout_s: float, into: memoryview | None = None) -> Frame | None:
        due = self.t0 + self.seq * self.period
        now = time.monotonic_ns()
        if due - now > timeout_s * 1e9:
            time.sleep(timeout_s)
            return None
        if due > now:
            time.sleep((due - now) / 1e9)
        src = self.frames[self.seq % len(self.frames)]
        assert into is not None
        into[: len(src)] = src
        f = Frame(self.name, self.seq, due, time.monotonic_ns(), FrameFlags.TIMESTAMP_MONOTONIC, into[: len(src)])
        self.seq += 1
        return f

    def stop(self) -> None: ...
    def close(self) -> None: ...
    def status(self) -> CameraStatus:
        return CameraStatus(True, self.fmt)


def rig_1080(fps: float):  # type: ignore[no-untyped-def]
    data = load_rig("sim-3x3").to_dict()
    data["format"].update(width_px=W, height_px=H, fps=fps)
    return rig_from_dict(data)


def record_at(
    fps: float, seconds: float, folder: Path, frames: list[bytes], checksum: bool = True
) -> tuple[bool, int, float, float]:
    rig = rig_1080(fps)
    t0 = time.monotonic_ns()
    cams = {n: PacedCamera(n, frames, fps, t0) for n in rig.camera_names}
    devices = DeviceSet(cameras=cams)  # type: ignore[arg-type]
    plan = TakePlan.spread(f"bench{fps:g}", [folder], rig.camera_names)
    rec = Recorder(rig, devices, plan, checksum=checksum)
    n = round(seconds * fps)
    cpu0 = time.process_time()
    rec.arm()
    rec.start(n)
    rec.wait(timeout_s=seconds * 3 + 10)
    man = rec.finish()
    wall = n / fps  # the take's own duration: the rate offered, written without a drop when ok
    cpu = time.process_time() - cpu0
    assert man is not None
    written = sum(c.frames for c in man.cameras.values())
    dropped = sum(len(c.writer_drops) + len(c.source_drops) + len(c.not_written) for c in man.cameras.values())
    nbytes = written * W * H * 2
    shutil.rmtree(folder / plan.name, ignore_errors=True)
    return dropped == 0 and written == 9 * n, nbytes, wall, cpu / max(written, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", type=Path, default=None, help="destination (default: a temp folder under /work)")
    parser.add_argument("--seconds", type=float, default=2.0)
    ns = parser.parse_args()
    base = ns.dir or Path(tempfile.mkdtemp(prefix="rigctl-bench-", dir="/work" if os.path.isdir("/work") else None))
    rng = np.random.default_rng(0)
    frames = [rng.integers(16, 235, W * H * 2, dtype=np.uint8).tobytes() for _ in range(4)]
    try:
        for checksum in (True, False):
            label = "with CRC-32" if checksum else "without CRC-32"
            lo, hi = 0, 60  # frames per second per camera; the highest without a drop is searched for
            best = None
            while hi - lo > 1:
                fps = (lo + hi) // 2
                ok, nbytes, wall, cpu_per_frame = record_at(fps, ns.seconds, base, frames, checksum)
                print(
                    f"  {label}: {fps:3d} fps x 9 {'ok' if ok else 'dropped'}, CPU {cpu_per_frame * 1e3:.2f} ms/frame"
                )
                if ok:
                    lo, best = fps, (fps, nbytes, wall, cpu_per_frame)
                else:
                    hi = fps
            if best is None:
                print(f"{label}: the recorder could not sustain 1 fps on this disk")
                continue
            fps, nbytes, wall, cpu_per_frame = best
            rec_rate = nbytes / wall
            plain = plain_write(base, nbytes)  # buffered write and one flush, as the recorder writes
            print(
                f"{label}: recorder sustains {fps} fps x 9 = {rec_rate / 1e6:.0f} MB/s; plain write of the same "
                f"{nbytes / 1e9:.2f} GB {plain / 1e6:.0f} MB/s; ratio {rec_rate / plain:.2f} (target >= 0.8); "
                f"CPU {cpu_per_frame * 1e3:.2f} ms per frame"
            )
    finally:
        if ns.dir is None:
            shutil.rmtree(base, ignore_errors=True)


def plain_write(folder: Path, nbytes: int) -> float:
    """Bytes/s of a plain buffered write of ``nbytes`` to ``folder`` and one fdatasync at the end."""
    path = folder / f".plain-{os.getpid()}"
    block = memoryview(os.urandom(4 << 20))
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        t0 = time.perf_counter()
        written = 0
        while written < nbytes:
            written += os.write(fd, block)
        os.fdatasync(fd)
        elapsed = time.perf_counter() - t0
    finally:
        os.close(fd)
        path.unlink(missing_ok=True)
    return written / max(elapsed, 1e-9)


if __name__ == "__main__":
    main()
