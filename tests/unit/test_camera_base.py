"""The camera base class owns the lifecycle, the buffer check and the counters, once for every driver."""

from __future__ import annotations

import pytest

from rigctl.camera_base import CameraBase, CameraState, SignalReport
from rigctl.errors import DeviceError
from rigctl.interfaces import CaptureFormat, Frame, FrameFlags

FMT = CaptureFormat(4, 2, "UYVY", 25.0)
PERIOD = 40_000_000


class ScriptedCamera(CameraBase):
    """Delivers the sequence numbers it is given (None: a timeout); reports gaps as source drops."""

    def __init__(self, sequences: list[int | None]) -> None:
        super().__init__("r0c0", "test://r0c0")
        self.sequences = list(sequences)
        self.calls: list[str] = []
        self._last: int | None = None

    def _do_open(self) -> None:
        self.calls.append("open")

    def _do_configure(self, fmt: CaptureFormat) -> CaptureFormat:
        if fmt.width != FMT.width:
            raise DeviceError(f"{self.address}: not offered")
        return FMT

    def _do_start(self) -> None:
        self.calls.append("start")
        self._last = None

    def _do_read(self, timeout_s: float, into: memoryview) -> Frame | None:
        seq = self.sequences.pop(0)
        if seq is None:
            return None
        if self._last is not None and seq > self._last + 1:
            self._count_source_drops(seq - self._last - 1)
        self._last = seq
        into[:4] = bytes([seq % 256] * 4)
        return Frame(self.name, seq, seq * PERIOD, seq * PERIOD, FrameFlags.NONE, into[: FMT.bytes_per_frame])

    def _do_stop(self) -> None:
        self.calls.append("stop")

    def _do_close(self) -> None:
        self.calls.append("close")

    def _signal_report(self) -> SignalReport:
        return SignalReport(present=True, detail="scripted")


def started(sequences: list[int | None]) -> ScriptedCamera:
    cam = ScriptedCamera(sequences)
    cam.open()
    cam.configure(FMT)
    cam.start()
    return cam


def test_counts_frames_gaps_and_rate() -> None:
    cam = started([0, 1, None, 4, 5])
    got = [cam.read(0.1) for _ in range(5)]
    assert [f.sequence if f else None for f in got] == [0, 1, None, 4, 5]
    st = cam.status()
    assert (st.frames, st.source_drops) == (4, 2)
    assert st.measured_fps == pytest.approx(15.0)  # 4 frames over 5 periods: what arrived, not the nominal
    assert st.format == FMT and st.detail == "scripted"


def test_restart_resets_the_counters() -> None:
    cam = started([0, 3, 0])
    cam.read(0.1), cam.read(0.1)
    assert cam.status().source_drops == 2
    cam.stop()
    cam.start()
    cam.read(0.1)
    st = cam.status()
    assert (st.frames, st.source_drops) == (1, 0)


def test_a_buffer_too_small_is_refused_before_the_device_is_touched() -> None:
    cam = started([0])
    with pytest.raises(DeviceError, match=r"test://r0c0: buffer of 3 bytes for a 16-byte frame"):
        cam.read(0.1, memoryview(bytearray(3)))
    assert cam.sequences == [0], "the device was read although the buffer could not hold the frame"


def test_states_and_idempotent_stop_close() -> None:
    cam = ScriptedCamera([])
    assert cam.state is CameraState.CLOSED
    cam.close()
    assert cam.calls == [], "closing a closed camera touched the device"
    cam.open()
    with pytest.raises(DeviceError, match="busy"):
        cam.open()
    with pytest.raises(DeviceError, match="not offered"):
        cam.configure(CaptureFormat(6, 2, "UYVY", 25.0))
    assert cam.state is CameraState.OPEN, "a refused format leaves the camera unconfigured"
    cam.configure(FMT)
    cam.start()
    cam.start()  # already streaming: no second STREAMON
    assert cam.calls.count("start") == 1
    cam.close()
    assert cam.calls == ["open", "start", "stop", "close"]
    assert cam.state is CameraState.CLOSED
