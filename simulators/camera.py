"""A simulated camera behind the :class:`~rigctl.interfaces.Camera` interface.

It behaves like a V4L2 capture device: sequence numbers restart at 0 on every start, frames arrive in
real time on the array's genlocked grid (plus the configured skew and jitter), a reader that falls more
than ``buffers`` frames behind loses frames at the source (sequence gaps), and a signal loss stops
delivery without advancing the sequence. Every frame carries its ids burnt into the top-left corner.

With ``deterministic=true`` the grid runs on a simulated clock instead: its origin is fixed, each frame is
delivered when the reader asks for it (no real-time pacing, so a slow reader loses nothing), its capture
and host times are the grid's (plus the seed's skew and jitter, and the latency), and configured drops and
signal losses still happen where they are set: the same frames, bytes and timestamps on any machine.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator

import cv2
import numpy as np
from numpy.typing import NDArray
from rigctl.simulators import burnin, sensor
from rigctl.simulators.array import FrameTiming, SimArray

from rigctl.camera_base import CameraBase, SignalReport
from rigctl.errors import DeviceError
from rigctl.interfaces import CaptureFormat, Frame, FrameFlags
from rigctl.yuv10 import is_ten_bit

log = logging.getLogger(__name__)


class SimCamera(CameraBase):
    """One ``sim://rXcY`` camera of a :class:`SimArray`."""

    def __init__(self, name: str, array: SimArray, buffers: int = 8, latency_us: float = 800.0) -> None:
        super().__init__(name, f"sim://{name}")
        self.array = array
        self.buffers = buffers
        self.latency_ns = int(latency_us * 1e3)
        self._timings: Iterator[FrameTiming] | None = None
        self._pending: FrameTiming | None = None
        self.delivering = False  # a frame delivered since the stream started
        self._t0 = 0  # the grid origin this camera's timings are on
        self._next_grid = 0  # deterministic: the grid slot after the last frame delivered
        self._last_rel = 0  # deterministic: the last frame's capture time from the origin (the simulated now)
        self.delivered: dict[int, int] = {}  # sequence -> scene frame, for the ground truth
        self._scratch: NDArray[np.uint16] | None = None  # a v210 camera's Y210 words before packing

    # lifecycle -------------------------------------------------------------------------------------
    def _do_open(self) -> None:
        self.array.claim(self.name)

    def _do_configure(self, fmt: CaptureFormat) -> CaptureFormat:
        have = self.array.format
        if (fmt.width, fmt.height, fmt.pixel_format) != (have.width, have.height, have.pixel_format):
            raise DeviceError(f"{self.address}: format {fmt.describe()} not offered (offered: {have.describe()})")
        if abs(fmt.fps - have.fps) > 1e-6:
            raise DeviceError(f"{self.address}: {fmt.fps:g} fps not offered (offered: {have.fps:g} fps)")
        return have

    def _do_start(self) -> None:
        if self.array.up_front:
            self.array.prime()  # every state is needed in real time from the first frame on
        else:
            # streams at once: the first frame waits for the first state, the rest render in the background
            self.array.render_in_background()
        self._t0 = self.array.start_stream()
        self._timings = self._timings_from_now(self._t0)
        self._pending = None
        self.delivering = False

    def _timings_from_now(self, t0: int) -> Iterator[FrameTiming]:
        if self.array.settings.deterministic:  # where the last stream left the simulated clock
            first_grid = self.array.resume_grid
        else:
            first_grid = max(0, -(-(time.monotonic_ns() - t0) // self.array.period_ns))
        return self.array.timing(self.name, first_grid=first_grid)

    def _do_stop(self) -> None:
        self.array.resume_grid = max(self.array.resume_grid, self._next_grid)
        self._timings = None
        self._pending = None

    def _do_close(self) -> None:
        self.array.release(self.name)

    # frames ----------------------------------------------------------------------------------------
    def _do_read(self, timeout_s: float, into: memoryview) -> Frame | None:
        assert self._timings is not None
        if self.array.settings.deterministic:
            return self._read_paced(timeout_s, into)
        deadline = time.monotonic_ns() + int(timeout_s * 1e9)
        while True:
            timing = self._pending or next(self._timings)
            self._pending = None
            state = self.array.state_of(timing.scene_frame)
            if not self.array.states.ready(state):
                # a state the background has not rendered yet (the first, or a machine slower than the
                # motion's schedule): the frame comes late, or is lost as a late frame is, never altered
                self._pending = timing
                if not self.array.states.wait(state, (deadline - time.monotonic_ns()) / 1e9):
                    return None
                continue
            if not self.delivering and not self.array.up_front:
                # the rig's grid begins with its first picture, not when the cameras started: the motion's
                # schedule counts from there, and every camera restarts its stream on that grid
                t0 = self.array.first_picture()
                if t0 != self._t0:
                    self._t0 = t0
                    self._timings = self._timings_from_now(t0)
                    continue
            t0 = self._t0
            due = t0 + timing.capture_ns + self.latency_ns
            now = time.monotonic_ns()
            if not timing.delivered:
                self._count_source_drops()
                continue
            if now - due > self.buffers * self.array.period_ns:
                # the reader fell behind: every driver buffer was full, the device dropped this frame
                self._count_source_drops()
                continue
            if due > deadline:
                self._pending = timing
                if deadline > now:
                    time.sleep((deadline - now) / 1e9)
                return None
            if due > now:
                time.sleep((due - now) / 1e9)
            return self._deliver(timing, t0, into)

    def _read_paced(self, timeout_s: float, into: memoryview) -> Frame | None:
        """Deterministic: the next frame on the simulated clock, at once, however late the reader asks; only
        its scene state's render is waited for (up to ``timeout_s``; the frame stays next)."""
        assert self._timings is not None
        while True:
            timing = self._pending or next(self._timings)
            self._pending = None
            if not timing.delivered:
                self._count_source_drops()
                continue
            if not self.array.states.wait(self.array.state_of(timing.scene_frame), timeout_s):
                self._pending = timing
                return None
            return self._deliver(timing, self._t0, into)

    def _deliver(self, timing: FrameTiming, t0: int, into: memoryview) -> Frame:
        arr = self.array
        state = arr.state_of(timing.scene_frame)
        clean = arr.frames(state)[arr.index[self.name]]
        gain = arr.gain_for(self.name)
        noise = arr.noise_for(self.name, timing.sequence)
        burn = (arr.index[self.name], timing.sequence, timing.scene_frame)
        if is_ten_bit(arr.format.pixel_format):
            if self._scratch is None:
                self._scratch = np.empty((arr.format.height, arr.format.width * 2), np.uint16)
            data = sensor.deliver10(clean, into, arr.format, gain, noise, self._scratch, burn)
        else:
            data = self._deliver8(clean, into, gain, noise, burn)
        capture = t0 + timing.capture_ns
        self.delivered[timing.sequence] = timing.scene_frame
        self.delivering = True
        flags = FrameFlags.TIMESTAMP_MONOTONIC | FrameFlags.TIMESTAMP_SOE
        if arr.settings.deterministic:
            self._next_grid, self._last_rel = timing.scene_frame + 1, timing.capture_ns
            host = capture + self.latency_ns
        else:
            host = time.monotonic_ns()
        return Frame(self.name, timing.sequence, capture, host, flags, data)

    def _deliver8(
        self,
        clean: NDArray[np.uint8],
        into: memoryview,
        gain: float,
        noise: NDArray[np.int16] | None,
        burn: tuple[int, int, int],
    ) -> memoryview:
        arr = self.array
        buf = np.frombuffer(into, dtype=np.uint8, count=clean.nbytes).reshape(clean.shape)
        if gain != 1.0:
            lut = arr.gain_lut(gain)
            cv2.LUT(clean.reshape(clean.shape[0], -1, 4), lut, dst=buf.reshape(clean.shape[0], -1, 4))
            src = buf
        else:
            src = clean
        if noise is not None:
            cv2.add(src, noise, dst=buf, dtype=cv2.CV_8U)
        elif src is not buf:
            np.copyto(buf, src)
        if arr.format.pixel_format in ("UYVY", "YUYV"):
            burnin.burn(buf, arr.format.width, *burn)
        return buf.reshape(-1).data

    def _signal_report(self) -> SignalReport:
        t0 = self.array.stream_start_ns
        if self.array.settings.deterministic:
            now_rel = self._last_rel
        else:
            now_rel = time.monotonic_ns() - t0 if t0 is not None else 0
        locked, reference = self.array.reference_locked(self.name)
        return SignalReport(
            present=self.array.signal_present(self.name, now_rel),
            detail=self.array.describe(),
            reference_locked=locked,
            extra={"reference": reference},
        )
