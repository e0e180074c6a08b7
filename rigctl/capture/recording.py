"""One take, start to finish, as a library call: preflight, arm, record, finish. ``rigctl record``, the shoot
UI's session and ``rigctl demo`` all go through :func:`preflight_take` (and the first and last through
:func:`record_take`), so the three decide and report alike.

It lives beside :mod:`rigctl.capture.recorder`, not in :mod:`rigctl.take`: the take package is kept free of device
code (it reads and writes folders), and recording opens devices through the registry."""

from __future__ import annotations

import logging
import signal
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

from rigctl.capture.preflight import PreflightReport, WriteSpeed, check_destinations, rate_text
from rigctl.capture.recorder import Recorder, TakePlan
from rigctl.errors import ParameterError, PreflightError
from rigctl.publish import NewFolders
from rigctl.registry import DeviceSet, open_cameras
from rigctl.rig import Rig
from rigctl.take.manifest import Manifest
from rigctl.take.names import check_take_name
from rigctl.take.plan import check_buffers
from rigctl.take.staging import Staging
from rigctl.yuv10 import is_ten_bit

log = logging.getLogger(__name__)

DROP_WARN_S = 30.0  # a writer queue that fills within this long is reported while recording


def preflight_take(
    rig: Rig,
    plan: TakePlan,
    frames: int | None,
    buffers_per_camera: int,
    speeds: dict[Path, WriteSpeed] | None = None,
    dirty_headroom: int | None = None,
) -> PreflightReport:
    """Preflight's verdict for ``plan``: every destination with its cameras, the planned length (``frames``
    frame sets, None: open-ended) and the recorder's pools."""
    fmt = Recorder.capture_format(rig)
    by_dest: dict[Path, list[str]] = {}
    for cam, folder in plan.camera_folders.items():
        by_dest.setdefault(folder.parent.parent, []).append(cam)
    duration = frames / rig.fps if frames else None
    camera_bps = fmt.stored_bytes_per_frame * fmt.fps  # what reaches the disk (10-bit: 20 bits a pixel)
    report = check_destinations(
        by_dest,
        camera_bps,
        duration,
        speeds,
        buffer_bytes_per_camera=buffers_per_camera * fmt.bytes_per_frame,
        dirty_headroom=dirty_headroom,
    )
    cameras = len(plan.camera_folders)
    stored = " stored at 20 bits a pixel" if is_ten_bit(fmt.pixel_format) else ""
    report.rate = (
        f"{rate_text(camera_bps)} a camera ({fmt.describe()}{stored}), "
        f"{rate_text(camera_bps * cameras)} for the array of {cameras}"
    )
    return report


def enforce(report: PreflightReport, force: bool) -> None:
    """Raise :class:`PreflightError` on a refusal, unless ``force`` may override it."""
    if report.ok:
        return
    problems = report.problems
    if force and report.forcible:
        log.warning("recording despite preflight (--force): %s", "; ".join(problems))
        return
    first = problems[0] + (f" (and {len(problems) - 1} more)" if len(problems) > 1 else "")
    raise PreflightError(first, problems, forcible=report.forcible)


class DropWatch:
    """Logs once when a writer queue's trend says a drop is near, and again when it has recovered."""

    def __init__(self, say: Callable[[str], None] | None = None, warn_s: float = DROP_WARN_S) -> None:
        self.say = say or (lambda text: log.warning("%s", text))
        self.warn_s = warn_s
        self.warned = False
        self.history: list[float | None] = []

    def __call__(self, left_s: float | None) -> None:
        self.history.append(left_s)
        if left_s is not None and left_s < self.warn_s and not self.warned:
            self.warned = True
            self.say(f"falling behind: a writer queue fills in about {left_s:.0f} s, then frames drop")
        elif self.warned and left_s is None:
            self.warned = False
            self.say("writers keep up again")


@dataclass
class TakeResult:
    folder: Path
    manifest: Manifest | None  # None: the take never started
    recorder: Recorder
    preflight: PreflightReport
    drop_watch: DropWatch = field(default_factory=DropWatch)


def record_take(
    rig: Rig,
    name: str,
    destinations: list[Path],
    *,
    frames: int | None = None,
    sim: list[str] | None = None,
    devices: DeviceSet | None = None,
    checksum: bool = True,
    buffers_per_camera: int | None = None,
    force: bool = False,
    progress: Callable[[float], None] | None = None,
    catch_interrupt: bool = False,
    say: Callable[[str], None] | None = None,
    on_preflight: Callable[[PreflightReport], object] | None = None,
) -> TakeResult:
    """Record ``frames`` frame sets (None: until :meth:`Recorder.stop`; with ``catch_interrupt``, Ctrl-C stops it) from
    every camera of ``rig`` into ``destinations[0]/name`` (cameras spread over the destinations). Preflight
    runs before the cameras stream; a refusal raises :class:`PreflightError` unless ``force``. The take's
    own failure (disk full, write error) is left in ``result.recorder.error`` with the take finalised.
    ``on_preflight`` sees the verdict with its figures before it is enforced; ``say`` gets what the writer
    queues' trend says while recording (default: a logged warning)."""
    name = check_take_name(name)
    if frames is not None and frames <= 0:
        raise ParameterError(f"frames must be a positive number of frame sets, got {frames}")
    if buffers_per_camera is not None:  # before the cameras are made: a pool too big is refused, not allocated
        check_buffers(buffers_per_camera, Recorder.capture_format(rig).bytes_per_frame, len(rig.cameras))
    made = NewFolders(*destinations)  # preflight makes the destinations: a run that keeps nothing removes them
    kept = False
    try:
        devices = devices or open_cameras(rig, list(sim or []))
        plan = TakePlan.spread(name, destinations, sorted(devices.cameras, key=rig.camera_names.index))
        buffers = buffers_per_camera or Recorder.default_buffers(Recorder.capture_format(rig))
        try:
            Staging(plan).check()  # the name taken, or a cut-off recording of it in the way: before preflight
            report = preflight_take(rig, plan, frames, buffers)
            for line in report.lines():
                log.info("%s", line)
            if on_preflight is not None:
                on_preflight(report)
            enforce(report, force)
        except BaseException:
            devices.close()
            raise
        recorder = Recorder(rig, devices, plan, checksum=checksum, buffers_per_camera=buffers)
        watch = DropWatch(say)
        previous: Any = None
        if catch_interrupt:
            previous = signal.getsignal(signal.SIGINT)

            def on_interrupt(signum: int, frame: FrameType | None) -> None:
                recorder.stop()

        try:
            recorder.arm()
            if catch_interrupt:
                signal.signal(signal.SIGINT, on_interrupt)
            recorder.start(frames)
            recorder.wait(progress=progress, watch=watch)
        finally:
            if catch_interrupt:
                signal.signal(signal.SIGINT, previous)
            manifest = recorder.finish()
        kept = manifest is not None
    finally:
        if not kept:
            made.remove_empty()
    return TakeResult(plan.folder, manifest, recorder, report, watch)
