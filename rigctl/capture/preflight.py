"""Checks before a take is armed: can each destination take what its cameras will send, and for how long?

Preflight is a model, not a single sample. For every destination it knows:

- the sustained write speed, from several samples written straight to the device (``O_DIRECT`` where the
  filesystem allows it, else write + ``fdatasync``), reported as median and low percentile;
- what the take needs: its cameras' data rate and its planned length (or open-ended);
- what can absorb a disk slower than the cameras for a while: the recorder's frame pools and the memory
  the kernel lets hold dirty pages before it throttles writers;
- the free space.

From these it decides one of three outcomes, each with its figures:

- **go**: the disk keeps up, or the buffers absorb the whole planned take;
- **warn**: the take may fall behind after about N seconds (buffers full at the low-percentile speed);
- **refuse**: cannot record: not writable, not enough space for the planned length, or a disk far below
  what the cameras need and no buffer that holds the take.

:func:`decide` is pure (figures in, verdict out) so every outcome is tested on injected speeds.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import mmap
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from rigctl.diskspace import free_bytes

log = logging.getLogger(__name__)

GO, WARN, REFUSE = "go", "warn", "refuse"
SAMPLES = 6
SAMPLE_BYTES = 16 << 20
BLOCK_BYTES = 4 << 20
MEASURE_BUDGET_S = 1.5  # stop sampling after this long once MIN_SAMPLES are in (a slow disk must not stall start)
MIN_SAMPLES = 3
LOW_PERCENTILE = 20.0
FAR_BELOW = 0.5  # below half the need with nothing to absorb the rest: refuse
LOW_TIME_S = 600.0  # less room than this on an open-ended take: a warning


@dataclass(frozen=True)
class WriteSpeed:
    """Write speed samples of one destination in bytes/s, and how they were taken."""

    samples_bps: tuple[float, ...]
    direct: bool = True  # O_DIRECT (the page cache bypassed); False: buffered writes flushed with fdatasync

    def percentile(self, q: float) -> float:
        s = sorted(self.samples_bps)
        if not s:
            return 0.0
        pos = (len(s) - 1) * q / 100.0
        lo = int(pos)
        hi = min(lo + 1, len(s) - 1)
        return s[lo] + (s[hi] - s[lo]) * (pos - lo)

    @property
    def median_bps(self) -> float:
        return self.percentile(50.0)

    @property
    def low_bps(self) -> float:
        return self.percentile(LOW_PERCENTILE)

    def describe(self) -> str:
        how = "O_DIRECT" if self.direct else "write+fdatasync"
        return (
            f"median {self.median_bps / 1e6:.0f} MB/s, p{LOW_PERCENTILE:.0f} {self.low_bps / 1e6:.0f} MB/s "
            f"({len(self.samples_bps)} samples, {how})"
        )


def _open_direct(path: Path) -> tuple[int, bool]:
    flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0)
    direct = getattr(os, "O_DIRECT", 0)
    if direct:
        try:
            return os.open(path, flags | direct, 0o600), True
        except OSError as exc:
            if exc.errno not in (errno.EINVAL, errno.EOPNOTSUPP):
                raise
    return os.open(path, flags, 0o600), False


def measure_write(
    folder: Path,
    samples: int = SAMPLES,
    sample_bytes: int = SAMPLE_BYTES,
    budget_s: float = MEASURE_BUDGET_S,
    clock: Callable[[], float] = time.perf_counter,
) -> WriteSpeed:
    """Sustained write speed of ``folder``'s device: ``samples`` timed runs of ``sample_bytes`` each, written
    with O_DIRECT from a page-aligned buffer (or, where the filesystem refuses O_DIRECT, written and flushed
    with fdatasync). Sampling stops early after ``budget_s`` once :data:`MIN_SAMPLES` are in. A sample is at
    most a quarter of the free space, and a destination that fills up while measuring ends the measurement
    with what it has: free space is the space check's business, not the speed test's."""
    folder.mkdir(parents=True, exist_ok=True)
    free = free_bytes(folder)
    sample_bytes = max(BLOCK_BYTES, min(sample_bytes, free // 4 // BLOCK_BYTES * BLOCK_BYTES))
    path = folder / f".rigctl-speedtest-{os.getpid()}"
    block = mmap.mmap(-1, BLOCK_BYTES)  # page-aligned, as O_DIRECT requires
    block.write(os.urandom(BLOCK_BYTES))
    fd, direct = _open_direct(path)
    out: list[float] = []
    try:
        start = clock()
        for _ in range(samples):
            t0 = clock()
            written = 0
            try:
                while written < sample_bytes:
                    try:
                        written += os.write(fd, block)
                    except OSError as exc:
                        if not (direct and exc.errno == errno.EINVAL):
                            raise
                        os.close(fd)  # the filesystem opened O_DIRECT but refuses its writes: buffered instead
                        fd, direct = os.open(path, os.O_WRONLY | os.O_TRUNC), False
                if not direct:
                    os.fdatasync(fd)
            except OSError as exc:
                if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
                    raise
                break
            out.append(written / max(clock() - t0, 1e-9))
            os.ftruncate(fd, 0)  # each sample starts on an empty file: the test never holds more than one
            os.lseek(fd, 0, os.SEEK_SET)
            if len(out) >= MIN_SAMPLES and clock() - start > budget_s:
                break
    finally:
        os.close(fd)
        block.close()
        path.unlink(missing_ok=True)
    return WriteSpeed(tuple(out), direct)


def dirty_headroom_bytes(meminfo: str | None = None, ratios: tuple[int, int, int, int] | None = None) -> int:
    """Memory the kernel lets writers fill with dirty pages before it throttles them: the midpoint of the
    background and foreground dirty limits (Linux starts throttling there), less what is dirty already.
    ``meminfo`` (text of /proc/meminfo) and ``ratios`` (dirty_background_bytes, dirty_background_ratio,
    dirty_bytes, dirty_ratio) are read from /proc when not given; 0 when they cannot be read."""
    try:
        if meminfo is None:
            meminfo = Path("/proc/meminfo").read_text()
        if ratios is None:
            vm = Path("/proc/sys/vm")
            names = ("dirty_background_bytes", "dirty_background_ratio", "dirty_bytes", "dirty_ratio")
            r = [int((vm / n).read_text()) for n in names]
            ratios = (r[0], r[1], r[2], r[3])
    except (OSError, ValueError):
        return 0
    info = {}
    for line in meminfo.splitlines():
        key, _, rest = line.partition(":")
        with contextlib.suppress(ValueError, IndexError):
            info[key.strip()] = int(rest.split()[0]) * 1024
    available = info.get("MemAvailable", 0)
    bg_bytes, bg_ratio, fg_bytes, fg_ratio = ratios
    background = bg_bytes or available * bg_ratio // 100
    foreground = fg_bytes or available * fg_ratio // 100
    dirty_now = info.get("Dirty", 0) + info.get("Writeback", 0)
    return max(0, (background + foreground) // 2 - dirty_now)


@dataclass(frozen=True)
class Verdict:
    """Preflight's decision for one destination, with the figures it was made from."""

    folder: Path
    outcome: str  # GO, WARN or REFUSE
    reason: str  # "keeps up", "absorbed", "falls behind", "low space", "not writable", "no space", "far below"
    message: str
    cameras: int = 0
    need_bps: float = 0.0
    speed: WriteSpeed | None = None
    free_bytes: int = 0
    absorb_bytes: int = 0
    duration_s: float | None = None
    falls_behind_after_s: float | None = None  # at the low-percentile speed; None: never within the take

    @property
    def forcible(self) -> bool:
        """A refusal ``--force`` may override: the take may still record (and end cleanly when full)."""
        return self.outcome == REFUSE and self.reason != "not writable"


def _mb(bps: float) -> str:
    return f"{bps / 1e6:.0f} MB/s"


def _span(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def decide(
    folder: Path,
    cameras: int,
    need_bps: float,
    duration_s: float | None,
    speed: WriteSpeed | None,
    free_bytes: int,
    absorb_bytes: int,
    error: str | None = None,
) -> Verdict:
    """The decision for one destination. ``need_bps``: what its cameras send; ``duration_s``: the planned
    length (None: open-ended); ``speed``: measured samples (None with ``error`` when the test write failed);
    ``absorb_bytes``: recorder pools plus dirty-page headroom, which carry a disk slower than the cameras
    until they fill."""
    base = Verdict(folder, GO, "", "", cameras=cameras, need_bps=need_bps, duration_s=duration_s)
    if error is not None or speed is None or not speed.samples_bps:
        why = error or "no write speed measured"
        return replace(base, outcome=REFUSE, reason="not writable", message=f"{folder}: cannot write: {why}")
    figures = replace(base, speed=speed, free_bytes=free_bytes, absorb_bytes=absorb_bytes)
    room_s = free_bytes / need_bps if need_bps > 0 else float("inf")
    what = f"{cameras} camera(s) need {_mb(need_bps)}"
    measured = f"writes {speed.describe()}"
    if duration_s is not None and room_s < duration_s:
        return replace(
            figures,
            outcome=REFUSE,
            reason="no space",
            message=f"{folder}: room for {_span(room_s)} of {cameras} camera(s) ({free_bytes / 1e9:.1f} GB free), "
            f"the take needs {_span(duration_s)}; free space, shorten the take, or add --dest",
        )
    low, median = speed.low_bps, speed.median_bps

    def fill_time(rate: float) -> float:
        return absorb_bytes / (need_bps - rate) if need_bps > rate else float("inf")

    behind = fill_time(low)
    buffers = f"{absorb_bytes / 1e9:.1f} GB of frame pools and dirty-page memory"
    if median < FAR_BELOW * need_bps and (duration_s is None or fill_time(median) < duration_s):
        length = "an open-ended take" if duration_s is None else f"a {_span(duration_s)} take"
        return replace(
            figures,
            outcome=REFUSE,
            reason="far below",
            message=f"{folder}: {measured}; {what}, far more than it sustains; {buffers} fill after "
            f"{_span(fill_time(median))} of {length}; use a faster disk, spread cameras over more destinations "
            "(--dest), give the take a length, or --force",
            falls_behind_after_s=behind,
        )
    if duration_s is not None and behind >= duration_s:
        reason = "keeps up" if low >= need_bps else "absorbed"
        extra = "" if low >= need_bps else f"; {buffers} absorb the {_span(duration_s)} take"
        if room_s < LOW_TIME_S:
            extra += f"; {_span(room_s)} of recording left on the destination"
        return replace(figures, outcome=GO, reason=reason, message=f"{folder}: {measured}; {what}{extra}")
    if behind == float("inf"):
        if duration_s is None and room_s < LOW_TIME_S:
            return replace(
                figures,
                outcome=WARN,
                reason="low space",
                message=f"{folder}: only {_span(room_s)} of recording left ({free_bytes / 1e9:.1f} GB free)",
            )
        return replace(figures, outcome=GO, reason="keeps up", message=f"{folder}: {measured}; {what}")
    return replace(
        figures,
        outcome=WARN,
        reason="falls behind",
        message=f"{folder}: {measured}; {what}; may fall behind after about {_span(behind)} ({buffers} fill at "
        f"the p{LOW_PERCENTILE:.0f} speed); writer drops follow unless the disk speeds up",
        falls_behind_after_s=behind,
    )


def rate_text(bps: float) -> str:
    """A data rate as people say it: MB/s below a GB/s, GB/s from there."""
    return f"{bps / 1e9:.2f} GB/s" if bps >= 1e9 else f"{bps / 1e6:.0f} MB/s"


@dataclass
class PreflightReport:
    verdicts: list[Verdict] = field(default_factory=list)
    rate: str = ""  # the data rate per camera and for the array, said before the verdicts

    @property
    def outcome(self) -> str:
        outcomes = {v.outcome for v in self.verdicts}
        return REFUSE if REFUSE in outcomes else WARN if WARN in outcomes else GO

    @property
    def ok(self) -> bool:
        return self.outcome != REFUSE

    @property
    def problems(self) -> list[str]:
        return [v.message for v in self.verdicts if v.outcome == REFUSE]

    @property
    def warnings(self) -> list[str]:
        return [v.message for v in self.verdicts if v.outcome == WARN]

    @property
    def forcible(self) -> bool:
        return all(v.forcible for v in self.verdicts if v.outcome == REFUSE)

    @property
    def falls_behind_after_s(self) -> float | None:
        times = [v.falls_behind_after_s for v in self.verdicts if v.falls_behind_after_s is not None]
        return min(times) if times else None

    def lines(self) -> list[str]:
        return ([f"data rate: {self.rate}"] if self.rate else []) + [
            f"preflight {v.outcome}: {v.message}" for v in self.verdicts
        ]


def check_destinations(
    folders: dict[Path, list[str]],
    bytes_per_second_per_camera: float,
    duration_s: float | None,
    speeds: dict[Path, WriteSpeed] | None = None,
    buffer_bytes_per_camera: int = 0,
    dirty_headroom: int | None = None,
    measure: Callable[[Path], WriteSpeed] = measure_write,
    free_space: Callable[[Path], int] = free_bytes,
) -> PreflightReport:
    """A verdict per destination for the cameras that write to it. ``speeds``: measured earlier (a
    destination measured while cameras stream in this process reads slower: the test writes wait for the
    interpreter between blocks); a destination not in it is measured now with ``measure``. Destinations on
    one device share the dirty-page headroom; each is given all of it (the model is per destination).
    ``free_space``: the bytes free on a destination (injected by tests, which must not depend on this disk)."""
    report = PreflightReport()
    headroom = dirty_headroom_bytes() if dirty_headroom is None else dirty_headroom
    for folder, cams in folders.items():
        need = bytes_per_second_per_camera * len(cams)
        try:
            speed = speeds[folder] if speeds and folder in speeds else measure(folder)
            free = free_space(folder)
        except OSError as exc:
            report.verdicts.append(decide(folder, len(cams), need, duration_s, None, 0, 0, exc.strerror or str(exc)))
            continue
        absorb = headroom + buffer_bytes_per_camera * len(cams)
        verdict = decide(folder, len(cams), need, duration_s, speed, free, absorb)
        log.info("preflight %s: %s", verdict.outcome, verdict.message)
        report.verdicts.append(verdict)
    return report
