"""What callers need from devices, as Protocols: drivers and simulators implement them alike.

A camera delivers :class:`Frame` objects; the recorder, the TUI and ``rigctl devices`` see only this
interface, and the rig file's device address alone decides which implementation stands behind it.
"""

from __future__ import annotations

import collections
import enum
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

from rigctl.timecode import Timecode


class FrameFlags(enum.IntFlag):
    """Per-frame flags, stored in the take's index next to each frame."""

    NONE = 0
    ERROR = 1  # the device marked the buffer as corrupted (V4L2_BUF_FLAG_ERROR)
    TIMECODE = 2  # the frame carries a timecode
    TIMESTAMP_MONOTONIC = 4  # capture timestamp is CLOCK_MONOTONIC
    TIMESTAMP_SOE = 8  # capture timestamp taken at start of exposure (else end of frame)
    FORMAT_CHANGED = 16  # first frame after the signal format changed
    DROP_FRAME = 32  # the frame's timecode counts drop-frame (29.97 / 59.94 DF)


@dataclass(frozen=True)
class CaptureFormat:
    """The format a camera delivers: size, pixel format (fourcc) and frame rate."""

    width: int
    height: int
    pixel_format: str
    fps: float

    @property
    def bytes_per_frame(self) -> int:
        return self.width * self.height * BYTES_PER_PIXEL[self.pixel_format]

    def describe(self) -> str:
        return f"{self.width}x{self.height} {self.pixel_format} {self.fps:g} fps"


BYTES_PER_PIXEL = {"UYVY": 2, "YUYV": 2, "BGR3": 3, "GREY": 1}


@dataclass(slots=True)
class Frame:
    """One captured frame: camera name, device sequence number, timestamps in ns, flags and the bytes.

    ``capture_ns`` is on CLOCK_MONOTONIC (what V4L2 reports for monotonic buffers); ``host_ns`` is when
    the host received it, on the same clock. ``data`` is the frame as captured, never modified.
    """

    camera: str
    sequence: int
    capture_ns: int
    host_ns: int
    flags: FrameFlags
    data: memoryview
    timecode: Timecode | None = None


@dataclass
class CameraStatus:
    """What a camera reports about itself, for preflight and the shoot UI."""

    signal_present: bool
    format: CaptureFormat | None
    measured_fps: float = 0.0
    source_drops: int = 0
    frames: int = 0
    reference_locked: bool | None = None  # None: the capture path cannot tell
    detail: str = ""
    extra: dict[str, str] = field(default_factory=dict)


@runtime_checkable
class Camera(Protocol):
    """A capture device. Lifecycle: open -> configure -> start -> read ... -> stop -> close."""

    name: str

    def open(self) -> None:
        """Acquire the device; raises :class:`~rigctl.errors.DeviceError` if missing or busy."""

    def configure(self, fmt: CaptureFormat) -> CaptureFormat:
        """Ask for ``fmt``; returns what the device will deliver or raises naming what it offers."""

    def start(self) -> None:
        """Start streaming."""

    def read(self, timeout_s: float, into: memoryview | None = None) -> Frame | None:
        """The next frame, copied into ``into`` when given (no allocation), or None on timeout."""

    def stop(self) -> None:
        """Stop streaming; frames not yet read are discarded by the device."""

    def close(self) -> None:
        """Release the device."""

    def status(self) -> CameraStatus:
        """Signal, format, measured rate and drops, without blocking capture."""


class RateMeter:
    """Frames per second over the last ``window`` capture timestamps: frames / time spanned. Unlike an average
    of instantaneous rates seeded by one interval, a burst of queued buffers at stream start cannot skew it
    for long."""

    def __init__(self, window: int = 25) -> None:
        self._stamps: collections.deque[int] = collections.deque(maxlen=window)

    def add(self, timestamp_ns: int) -> None:
        if not self._stamps or timestamp_ns > self._stamps[-1]:
            self._stamps.append(timestamp_ns)

    def reset(self) -> None:
        self._stamps.clear()

    @property
    def fps(self) -> float:
        if len(self._stamps) < 2:
            return 0.0
        return (len(self._stamps) - 1) * 1e9 / (self._stamps[-1] - self._stamps[0])
