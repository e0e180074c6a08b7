"""The behaviour every camera shares, kept once: the lifecycle state machine, buffer checks and counters.

A driver or simulator subclasses :class:`CameraBase` and implements the ``_do_*`` steps only (the
template-method pattern of python-microscope's device base classes). The base class checks that each
call is legal in the current state, that a caller's buffer can hold a frame, counts frames and source
drops, measures the rate from capture timestamps, and builds the :class:`~rigctl.interfaces.CameraStatus`
from the subclass's view of its signal.
"""

from __future__ import annotations

import abc
import collections
import enum
import threading
from dataclasses import dataclass, field

from rigctl.errors import DeviceError
from rigctl.interfaces import CameraStatus, CaptureFormat, Frame


class CameraState(enum.Enum):
    """Where a camera is in its lifecycle: closed -> open -> configured -> streaming (and back)."""

    CLOSED = "closed"
    OPEN = "open"
    CONFIGURED = "configured"
    STREAMING = "streaming"


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


@dataclass
class SignalReport:
    """What a subclass knows about its input right now, for :meth:`CameraBase.status`."""

    present: bool
    detail: str = ""
    reference_locked: bool | None = None  # None: the capture path cannot tell
    extra: dict[str, str] = field(default_factory=dict)


class CameraBase(abc.ABC):
    """A camera whose lifecycle, buffer checks and counters are enforced here, once.

    Subclasses implement :meth:`_do_open`, :meth:`_do_configure`, :meth:`_do_start`, :meth:`_do_read`,
    :meth:`_do_stop`, :meth:`_do_close` and :meth:`_signal_report`; they call :meth:`_count_source_drops`
    when the device loses frames. Every public method raises :class:`~rigctl.errors.DeviceError` naming the
    camera's address when called in the wrong state.
    """

    def __init__(self, name: str, address: str) -> None:
        self.name = name
        self.address = address
        self.state = CameraState.CLOSED
        self.format: CaptureFormat | None = None
        self._counter_lock = threading.Lock()
        self._frames = 0
        self._source_drops = 0
        self._rate = RateMeter()

    # lifecycle -------------------------------------------------------------------------------------
    def open(self) -> None:
        """Acquire the device; raises DeviceError when missing, busy, or already open through this object."""
        if self.state is not CameraState.CLOSED:
            raise DeviceError(f"{self.address}: device is busy (already open)")
        self._do_open()
        self.state = CameraState.OPEN

    def configure(self, fmt: CaptureFormat) -> CaptureFormat:
        """Ask for ``fmt``; returns what the device delivers, or raises DeviceError naming what it offers."""
        if self.state is CameraState.CLOSED:
            raise DeviceError(f"{self.address}: configure before open")
        if self.state is CameraState.STREAMING:
            raise DeviceError(f"{self.address}: configure while streaming (stop first)")
        got = self._do_configure(fmt)
        self.format = got
        self.state = CameraState.CONFIGURED
        return got

    def start(self) -> None:
        """Start streaming; sequence numbers restart at 0 and the counters are reset."""
        if self.state is CameraState.STREAMING:
            return
        if self.state is not CameraState.CONFIGURED:
            raise DeviceError(f"{self.address}: start before configure")
        with self._counter_lock:
            self._frames = self._source_drops = 0
            self._rate.reset()
        self._do_start()
        self.state = CameraState.STREAMING

    def read(self, timeout_s: float, into: memoryview | None = None) -> Frame | None:
        """The next frame, copied into ``into`` when given (no allocation), or None on timeout. Raises
        DeviceError when not streaming or when ``into`` cannot hold a frame."""
        if self.state is not CameraState.STREAMING or self.format is None:
            raise DeviceError(f"{self.address}: read while not streaming")
        size = self.format.bytes_per_frame
        if into is not None and len(into) < size:
            raise DeviceError(f"{self.address}: buffer of {len(into)} bytes for a {size}-byte frame")
        frame = self._do_read(timeout_s, into if into is not None else memoryview(bytearray(size)))
        if frame is not None:
            with self._counter_lock:
                self._frames += 1
                self._rate.add(frame.capture_ns)
        return frame

    def stop(self) -> None:
        """Stop streaming; frames not yet read are discarded. Harmless when not streaming."""
        if self.state is CameraState.STREAMING:
            self.state = CameraState.CONFIGURED
            self._do_stop()

    def close(self) -> None:
        """Release the device (stopping it first). Harmless when closed."""
        self.stop()
        if self.state is not CameraState.CLOSED:
            self.state = CameraState.CLOSED
            self._do_close()

    def status(self) -> CameraStatus:
        """Signal, format, measured rate and drops, without blocking capture."""
        signal = self._signal_report()
        streaming = self.state is CameraState.STREAMING
        with self._counter_lock:
            return CameraStatus(
                signal_present=signal.present,
                format=self.format if signal.present else None,
                measured_fps=self._rate.fps if streaming else 0.0,
                source_drops=self._source_drops,
                frames=self._frames,
                reference_locked=signal.reference_locked,
                detail=signal.detail,
                extra=signal.extra,
            )

    def _count_source_drops(self, n: int = 1) -> None:
        with self._counter_lock:
            self._source_drops += n

    # what a subclass provides ----------------------------------------------------------------------
    @abc.abstractmethod
    def _do_open(self) -> None: ...

    @abc.abstractmethod
    def _do_configure(self, fmt: CaptureFormat) -> CaptureFormat: ...

    @abc.abstractmethod
    def _do_start(self) -> None: ...

    @abc.abstractmethod
    def _do_read(self, timeout_s: float, into: memoryview) -> Frame | None:
        """The next frame in ``into`` (already checked to be large enough), or None on timeout."""

    @abc.abstractmethod
    def _do_stop(self) -> None: ...

    @abc.abstractmethod
    def _do_close(self) -> None: ...

    @abc.abstractmethod
    def _signal_report(self) -> SignalReport: ...
