"""Checks before a take is armed: destinations fast and large enough, every camera delivering the format.

Refusing to arm is cheap; a take that drops frames because the disk could not keep up is not.
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

from rigctl.errors import RigctlError

SPEED_MARGIN = 1.25
TEST_BYTES = 64 << 20
LOW_TIME_S = 600.0


class PreflightError(RigctlError):
    """Preflight found a reason not to record; ``--force`` records anyway where that is safe to try."""

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        super().__init__(message)
        self.problems = problems or [message]


@dataclass
class DestinationCheck:
    path: Path
    cameras: list[str]
    required_bps: float
    measured_bps: float
    free_bytes: int

    @property
    def seconds_left(self) -> float:
        return self.free_bytes / self.required_bps if self.required_bps else float("inf")

    @property
    def fast_enough(self) -> bool:
        return self.measured_bps >= SPEED_MARGIN * self.required_bps


@dataclass
class PreflightReport:
    destinations: list[DestinationCheck] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def measure_write_speed(folder: Path, nbytes: int = TEST_BYTES) -> float:
    """Sustained write speed of ``folder``'s device in bytes/s: write and flush to the device."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f".rigctl-speedtest-{os.getpid()}"
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


def check_destinations(
    folders: dict[Path, list[str]],
    bytes_per_second_per_camera: float,
    duration_s: float | None,
    speeds: dict[Path, float] | None = None,
) -> PreflightReport:
    """Speed and space per destination for the cameras that write to it. ``speeds``: write speeds measured
    earlier (a destination measured while cameras stream in this process would be measured slow: the test
    writes wait for the interpreter between blocks); a destination not in it is measured now."""
    report = PreflightReport()
    for folder, cams in folders.items():
        try:
            speed = speeds[folder] if speeds and folder in speeds else measure_write_speed(folder)
            free = shutil.disk_usage(folder).free
        except OSError as exc:
            report.problems.append(f"{folder}: cannot write: {exc.strerror}")
            continue
        need = bytes_per_second_per_camera * len(cams)
        check = DestinationCheck(folder, cams, need, speed, free)
        report.destinations.append(check)
        if not check.fast_enough:
            report.problems.append(
                f"{folder}: sustains {speed / 1e6:.0f} MB/s, {len(cams)} camera(s) need {need / 1e6:.0f} MB/s "
                f"(x{SPEED_MARGIN} margin: {SPEED_MARGIN * need / 1e6:.0f} MB/s); use a faster disk, spread cameras "
                "over more destinations, or --force"
            )
        if duration_s is not None and check.seconds_left < duration_s:
            report.problems.append(
                f"{folder}: room for {check.seconds_left:.0f} s of {len(cams)} camera(s), the take needs "
                f"{duration_s:.0f} s"
            )
        elif check.seconds_left < LOW_TIME_S:
            report.warnings.append(f"{folder}: only {check.seconds_left / 60:.1f} minutes of recording left")
    return report
