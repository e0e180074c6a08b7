"""The V4L2 implementation of the :class:`~rigctl.interfaces.Camera` interface."""

from __future__ import annotations

import logging
import time

from rigctl.drivers.v4l2 import structs as S
from rigctl.drivers.v4l2.device import KernelTimecode, V4L2Device

from rigctl.camera_base import CameraBase, SignalReport
from rigctl.errors import DeviceError
from rigctl.interfaces import CaptureFormat, Frame, FrameFlags
from rigctl.timecode import Timecode, TimecodeError

log = logging.getLogger(__name__)

SIGNAL_CHECK_S = 1.0  # how often a streaming camera re-reads its input's DV timings


class V4L2Camera(CameraBase):
    """A rig camera on a V4L2 capture node (SDI or HDMI input, or any V4L2 capture device)."""

    def __init__(self, name: str, address: str, buffers: int = 8) -> None:
        super().__init__(name, address)
        self.buffers = buffers
        self.device = V4L2Device(address)
        self._bad_timecode = False
        self._last_seq: int | None = None
        self._next_signal_check = 0.0
        self._format_changed = False
        self._signal: str = ""
        self._repeats = 0

    def _do_open(self) -> None:
        self.device.open()

    def _do_configure(self, fmt: CaptureFormat) -> CaptureFormat:
        dev = self.device
        if dev.has_dv_timings():
            # SDI/HDMI inputs: the format follows the input's timings, so set those first
            dev.set_dv_timings(fmt.width, fmt.height, fmt.fps)
        dev.set_format(fmt.width, fmt.height, fmt.pixel_format)
        rate = dev.set_rate(fmt.fps) if not dev.has_dv_timings() else dev.dv_timings().fps
        if rate and abs(rate - fmt.fps) > 0.01 * fmt.fps:
            w, h, fourcc, _ = dev.get_format()
            offered = ", ".join(f"{r:g}" for r in dev.frame_rates(fourcc, w, h)) or "unknown"
            raise DeviceError(f"{self.address}: {fmt.fps:g} fps not offered (offered: {offered} fps)")
        w, h, fourcc, size = dev.get_format()
        got = CaptureFormat(w, h, fourcc, rate or fmt.fps)
        if size < got.bytes_per_frame:
            raise DeviceError(f"{self.address}: driver frames of {size} bytes, {fourcc} {w}x{h} needs more")
        return got

    def _do_start(self) -> None:
        self._repeats = 0
        self._last_seq = None
        self.device.start(self.buffers)

    def _do_read(self, timeout_s: float, target: memoryview) -> Frame | None:
        assert self.format is not None
        size = self.format.bytes_per_frame
        got = self.device.dequeue(timeout_s, target)
        if got is None:
            self._check_signal()
            return None
        host = time.monotonic_ns()
        flags = FrameFlags.NONE
        if got.flags & S.BUF_FLAG_ERROR or got.size < size:
            flags |= FrameFlags.ERROR  # corrupted or short: counted as a drop by the recorder
        if got.flags & S.BUF_FLAG_TIMESTAMP_MASK == S.BUF_FLAG_TIMESTAMP_MONOTONIC:
            flags |= FrameFlags.TIMESTAMP_MONOTONIC
        if got.flags & S.BUF_FLAG_TSTAMP_SRC_MASK == S.BUF_FLAG_TSTAMP_SRC_SOE:
            flags |= FrameFlags.TIMESTAMP_SOE
        tc = self._timecode(got.timecode)
        if tc is not None:
            flags |= FrameFlags.TIMECODE | (FrameFlags.DROP_FRAME if tc.drop else FrameFlags.NONE)
        seq = got.sequence
        if self._last_seq is not None and seq <= self._last_seq:
            # a driver that numbers frames from elapsed time (vivid under load) can hand out a number
            # twice, then skip one: the frame is real, so it gets the next free number; the later skip
            # brings the numbering back in step, and a real drop still shows as a gap
            self._repeats += 1
            if self._repeats == 1:
                log.warning("%s: driver repeated sequence number %d; renumbering to keep order", self.address, seq)
            seq = self._last_seq + 1
        if self._last_seq is not None and seq > self._last_seq + 1:
            self._count_source_drops(seq - self._last_seq - 1)
        self._last_seq = seq
        self._check_signal()
        if self._format_changed:
            flags |= FrameFlags.FORMAT_CHANGED
            self._format_changed = False
        return Frame(self.name, seq, got.timestamp_ns, host, flags, target[:size], tc)

    def _timecode(self, raw: KernelTimecode | None) -> Timecode | None:
        """The frame's timecode as a value; a label that cannot exist is left out (warned once), not guessed."""
        if raw is None or self.format is None:
            return None
        try:
            return raw.to_timecode(self.format.fps)
        except TimecodeError as exc:
            if not self._bad_timecode:
                log.warning("%s: driver sent timecode fields %s: %s; frames without a timecode", self.address, raw, exc)
            self._bad_timecode = True
            return None

    def _check_signal(self) -> None:
        """Once a second: has the input's signal format changed under us? (the take records it and goes on)"""
        now = time.monotonic()
        if now < self._next_signal_check or self.format is None or not self.device.has_dv_timings():
            return
        self._next_signal_check = now + SIGNAL_CHECK_S
        t = self.device.query_dv_timings()
        fmt = self.format
        now_signal = "none" if t is None else t.describe()
        changed = t is not None and ((t.width, t.height) != (fmt.width, fmt.height) or abs(t.fps - fmt.fps) > 0.05)
        if changed and now_signal != self._signal:
            log.warning("%s: input signal changed to %s (capturing %s)", self.address, now_signal, fmt.describe())
            self._format_changed = True
        self._signal = now_signal

    def _do_stop(self) -> None:
        self.device.stop()

    def _do_close(self) -> None:
        self.device.close()

    def _signal_report(self) -> SignalReport:
        dev = self.device
        present = True
        detail = ""
        if dev.fd >= 0 and dev.has_dv_timings():
            t = dev.query_dv_timings()
            present = t is not None
            detail = "no signal" if t is None else f"input {t.describe()}"
        elif dev.fd >= 0:
            present = not dev.input_status() & (S.IN_ST_NO_SIGNAL | S.IN_ST_NO_POWER)
        # V4L2 does not say whether the camera is locked to reference; camera control does
        extra = {"sequence_repeats": str(self._repeats)} if self._repeats else {}
        return SignalReport(present=present, detail=detail, reference_locked=None, extra=extra)
