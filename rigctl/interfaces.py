"""What callers need from devices, as Protocols, and the values that cross them: drivers and simulators
implement them alike.

A camera delivers :class:`Frame` objects; a tally output takes a whole :class:`TallyState`; a camera-control
path applies settings and reports a :class:`SettingResult` with a :class:`SettingState` per camera and
setting. The recorder, the TUI and the CLI see only these interfaces, and the rig file's device address
alone decides which implementation stands behind them (:mod:`rigctl.registry`). Every method that talks to
a device raises :class:`~rigctl.errors.DeviceError` (naming the device) when the device fails; nothing
else escapes.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from rigctl.timecode import Timecode
from rigctl.yuv10 import device_frame_bytes, essence_frame_bytes, is_ten_bit

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from rigctl.calibration_model import ArrayCalibration
    from rigctl.rectification.geometry import RectifiedGrid
    from rigctl.take.manifest import Rectification


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
        """A frame as the device delivers it (v210's line padding included)."""
        if is_ten_bit(self.pixel_format):
            return device_frame_bytes(self.pixel_format, self.width, self.height)
        return self.width * self.height * BYTES_PER_PIXEL[self.pixel_format]

    @property
    def stored_bytes_per_frame(self) -> int:
        """A frame as a take stores it: 10-bit formats packed at 20 bits a pixel, the others as captured."""
        size = stored_frame_bytes(self.pixel_format, self.width, self.height)
        assert size is not None
        return size

    def describe(self) -> str:
        return f"{self.width}x{self.height} {self.pixel_format} {self.fps:g} fps"


BYTES_PER_PIXEL = {"UYVY": 2, "YUYV": 2, "BGR3": 3, "GREY": 1}


def stored_frame_bytes(pixel_format: str, width: int, height: int) -> int | None:
    """Bytes of one frame of ``pixel_format`` in a take's essence; None for a format rigctl does not read."""
    if is_ten_bit(pixel_format):
        return essence_frame_bytes(width, height) if width % 2 == 0 else None
    per_pixel = BYTES_PER_PIXEL.get(pixel_format)
    return None if per_pixel is None else width * height * per_pixel


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
    """A capture device. Lifecycle: open -> configure -> start -> read ... -> stop -> close.

    :class:`~rigctl.camera_base.CameraBase` implements the lifecycle checks once; drivers subclass it.
    """

    name: str

    def open(self) -> None:
        """Acquire the device; raises DeviceError if missing or busy."""

    def configure(self, fmt: CaptureFormat) -> CaptureFormat:
        """Ask for ``fmt``; returns what the device will deliver, or raises DeviceError naming what it offers."""

    def start(self) -> None:
        """Start streaming; raises DeviceError before configure. Sequence numbers restart at 0."""

    def read(self, timeout_s: float, into: memoryview | None = None) -> Frame | None:
        """The next frame, copied into ``into`` when given (no allocation), or None on timeout. Raises
        DeviceError when not streaming, when ``into`` is too small, or when the device fails."""

    def stop(self) -> None:
        """Stop streaming; frames not yet read are discarded by the device. Never raises when not streaming."""

    def close(self) -> None:
        """Release the device. Never raises when already closed."""

    def status(self) -> CameraStatus:
        """Signal, format, measured rate and drops, without blocking capture."""


@dataclass(frozen=True)
class TallyState:
    """Which cameras are on program (live) and on preview: the whole truth, always sent whole."""

    program: frozenset[str] = field(default_factory=frozenset)
    preview: frozenset[str] = field(default_factory=frozenset)

    @classmethod
    def recording(cls, cameras: list[str]) -> TallyState:
        """A recording take puts every camera on program."""
        return cls(program=frozenset(cameras))


class TallyOutput(Protocol):
    """Where tally goes: a TSL UMD line, embedded tally through the SDI bridge, ..."""

    def send(self, state: TallyState) -> None:
        """Send the complete state; raises DeviceError when the line fails (the service reopens it)."""

    def settle(self) -> None:
        """After a one-shot send (``rigctl tally``): raises DeviceError when the receiver is seen to drop what
        was sent (a TCP receiver that closes or resets the connection at once); returns at once where no
        receiver can say so."""

    def close(self) -> None:
        """Release the line. Never raises."""


class SettingState(enum.StrEnum):
    """How far a camera setting is known to have been applied. Nothing is shown as applied on faith.
    A string enum, so reports and JSON carry the plain words."""

    CONFIRMED = "confirmed"  # the camera's own report matches
    UNCONFIRMED = "unconfirmed"  # sent, but the path cannot read the value back
    MISMATCH = "MISMATCH"  # the camera reports something else
    FAILED = "FAILED"  # the command did not get through

    @property
    def is_problem(self) -> bool:
        return self in (SettingState.MISMATCH, SettingState.FAILED)


@dataclass(frozen=True)
class SettingResult:
    """One camera's outcome for one setting."""

    camera: str
    setting: str
    requested: float | str
    state: SettingState
    reported: float | str | None = None
    detail: str = ""


class CameraControl(Protocol):
    """How settings reach the cameras (an SDI bridge, a camera's own network API, ...)."""

    description: str
    can_confirm: bool

    def apply(self, values: dict[str, float | str], cameras: list[str]) -> list[SettingResult]:
        """Send ``values`` to ``cameras`` and report each one's state. A failure to reach a camera is a
        FAILED result, not an exception; raises DeviceError only when the path itself is gone."""

    def close(self) -> None:
        """Release the path. Never raises."""


class TruthProvider(Protocol):
    """Something that knows what the cameras really saw (only a simulation can)."""

    def write_truth(self, folder: Path, frame_sets: list[tuple[int, dict[str, int]]]) -> None:
        """Write ``truth/`` for frame sets given as (number, {camera: sequence number})."""

    def rectification(self) -> Rectification | None:
        """The rectified geometry the frames already are in (an ideal simulation: its true calibration's
        common plane), for the take's manifest; None when the frames need ``rigctl rectify``."""


class SimulatedArray(Protocol):
    """A simulated array as the demo and the benchmarks read it without recording a take: its cameras and
    format, its true calibration and their common plane, each scene state's rendered frames (one per
    camera, in ``names`` order) and exact truth (per camera: disparity, +inf off the subject, and the
    subject matte), and where the subject lies (near, far in metres)."""

    names: list[str]
    format: CaptureFormat

    @property
    def calibration(self) -> ArrayCalibration: ...

    @property
    def rectified(self) -> RectifiedGrid: ...

    def frames(self, state: int) -> list[NDArray[np.uint8]]: ...

    def truth(self, state: int) -> tuple[list[NDArray[np.float32]], list[NDArray[np.bool_]]]: ...

    def near_far(self) -> tuple[float, float]: ...

    def close(self) -> None:
        """Stop its background work (rendering) and wait for what is under way."""
