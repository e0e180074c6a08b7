"""``rigctl bench record``: how fast the recorder stores 10-bit frames beside 8-bit ones, in one run.

Nine stand-in cameras hand the recorder pre-made frames as fast as it reads them, on a simulated clock
(paced, as ``--sim deterministic=true`` is: the recorder waits for a free buffer instead of dropping), so
the figure is the recorder's own ceiling on this machine and destination: capture copies, the 10-bit
repacking (device layout to 20 bits a pixel), CRC-32, writes and flushes. The formats take turns round by
round (a shared disk's mood falls on all of them alike) and each keeps its median. Page cache absorbs much
of a short take: the figure is the recorder's, a disk's sustained speed is preflight's to measure.
"""

from __future__ import annotations

import shutil
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rigctl.capture.recorder import Recorder
from rigctl.interfaces import CameraStatus, CaptureFormat, Frame, FrameFlags
from rigctl.registry import DeviceSet
from rigctl.rig import Rig, load_rig, rig_from_dict
from rigctl.take.plan import TakePlan
from rigctl.yuv10 import is_ten_bit, to_device

FORMATS = ("UYVY", "Y210", "v210")
UHD_25P_BPS = 3840 * 2160 * 25  # pixels a second of one UHD 25p camera


class StandInCamera:
    """Delivers its frames the moment it is read, one frame period apart on a simulated clock."""

    def __init__(self, name: str, frames: list[bytes], fmt: CaptureFormat) -> None:
        self.name, self.frames, self.fmt = name, frames, fmt
        self.period = round(1e9 / fmt.fps)
        self.seq = 0

    def open(self) -> None: ...
    def configure(self, fmt: CaptureFormat) -> CaptureFormat:
        return self.fmt

    def start(self) -> None:
        self.seq = 0

    def read(self, timeout_s: float, into: memoryview | None = None) -> Frame | None:
        src = self.frames[self.seq % len(self.frames)]
        assert into is not None
        into[: len(src)] = src  # what a capture card's DMA does, here on the CPU
        t = 1_000_000_000 + self.seq * self.period
        frame = Frame(self.name, self.seq, t, t, FrameFlags.TIMESTAMP_MONOTONIC, into[: len(src)])
        self.seq += 1
        return frame

    def stop(self) -> None: ...
    def close(self) -> None: ...
    def status(self) -> CameraStatus:
        return CameraStatus(True, self.fmt)


@dataclass(frozen=True)
class Throughput:
    """One format's median over the rounds: frames a second per camera, bytes stored a second (all cameras),
    CPU per frame."""

    pixel_format: str
    fps: float
    stored_bps: float
    device_bps: float
    cpu_per_frame_s: float
    stored_bytes_per_frame: int
    device_bytes_per_frame: int


def _rig(base: Rig, pixel_format: str, width: int, height: int) -> Rig:
    data = base.to_dict()
    data["format"].update(width_px=width, height_px=height, pixel_format=pixel_format, fps=25)
    return rig_from_dict(data)


def _frames(fmt: CaptureFormat, count: int = 3) -> list[bytes]:
    rng = np.random.default_rng(0)
    if is_ten_bit(fmt.pixel_format):
        codes = [rng.integers(64, 941, (fmt.height, fmt.width * 2)).astype(np.uint16) for _ in range(count)]
        return [to_device(c, fmt.pixel_format).tobytes() for c in codes]
    return [rng.integers(16, 236, fmt.bytes_per_frame, dtype=np.uint8).tobytes() for _ in range(count)]


def record_once(rig: Rig, folder: Path, frames: int, pictures: list[bytes]) -> tuple[float, float, int]:
    """(seconds, CPU seconds, frames stored) of one take of ``frames`` frame sets as fast as it goes."""
    fmt = Recorder.capture_format(rig)
    cams = {n: StandInCamera(n, pictures, fmt) for n in rig.camera_names}
    devices = DeviceSet(cameras=cams, paced=True)  # type: ignore[arg-type]
    plan = TakePlan.spread("bench-record", [folder], rig.camera_names)
    rec = Recorder(rig, devices, plan)
    try:
        rec.arm()  # the 10-bit kernels are loaded here, before the clock starts
        wall0, cpu0 = time.perf_counter(), time.process_time()
        rec.start(frames)
        rec.wait(timeout_s=600)
        manifest = rec.finish()
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    finally:
        shutil.rmtree(folder / plan.name, ignore_errors=True)
    stored = sum(c.frames for c in manifest.cameras.values()) if manifest else 0
    return wall, cpu, stored


def bench_record(
    folder: Path, width: int = 1920, height: int = 1080, frames: int = 25, rounds: int = 3
) -> list[Throughput]:
    """Every format of :data:`FORMATS` recorded ``rounds`` times, taking turns; medians."""
    base = load_rig("sim-3x3")
    rigs = {pf: _rig(base, pf, width, height) for pf in FORMATS}
    pictures = {pf: _frames(Recorder.capture_format(r)) for pf, r in rigs.items()}
    runs: dict[str, list[tuple[float, float, int]]] = {pf: [] for pf in FORMATS}
    for _ in range(rounds):
        for pf in FORMATS:
            runs[pf].append(record_once(rigs[pf], folder, frames, pictures[pf]))
    out = []
    for pf in FORMATS:
        fmt = Recorder.capture_format(rigs[pf])
        cams = len(rigs[pf].camera_names)
        fps = statistics.median(n / cams / wall for wall, _, n in runs[pf])
        cpu = statistics.median(c / max(n, 1) for _, c, n in runs[pf])
        stored, device = fmt.stored_bytes_per_frame, fmt.bytes_per_frame
        out.append(Throughput(pf, fps, fps * cams * stored, fps * cams * device, cpu, stored, device))
    return out


def format_bench(results: list[Throughput], width: int, height: int, frames: int, rounds: int) -> str:
    by = {r.pixel_format: r for r in results}
    lines = [
        f"recorder throughput: nine {width}x{height} streams as fast as the recorder stores them "
        f"({frames} frame sets a take, median of {rounds} rounds taking turns; page cache absorbs much of it):"
    ]
    for r in results:
        bits = "10-bit" if is_ten_bit(r.pixel_format) else "8-bit"
        packing = (
            f", stored at 20 bits a pixel from {r.device_bytes_per_frame / 1e6:.1f} MB" if bits == "10-bit" else ""
        )
        lines.append(
            f"  {r.pixel_format} {bits:>6}: {r.fps:5.1f} fps x 9 = {r.stored_bps / 1e9:.2f} GB/s stored "
            f"({r.stored_bytes_per_frame / 1e6:.1f} MB a frame{packing}), CPU {r.cpu_per_frame_s * 1e3:.1f} ms a frame"
        )
    eight = by["UYVY"]
    for pf in ("Y210", "v210"):
        ten = by[pf]
        lines.append(
            f"  {pf} / UYVY: frames {ten.fps / eight.fps:.2f}x, bytes stored {ten.stored_bps / eight.stored_bps:.2f}x"
        )
    need = UHD_25P_BPS * 20 / 8
    best = max(by["Y210"].stored_bps, by["v210"].stored_bps)
    lines.append(
        f"  a UHD 25p 10-bit camera stores {need / 1e9:.2f} GB/s, nine {9 * need / 1e9:.2f} GB/s; the recorder "
        f"reached {best / 1e9:.2f} GB/s of 10-bit here ({best / (9 * need):.0%} of nine)"
    )
    return "\n".join(lines)
