"""The Camera contract: what every implementation (simulator, V4L2 driver) must do.

Each test takes a ``make_camera`` fixture: a callable returning an unopened camera and the format to
configure. ``test_camera_contract_sim.py`` binds it to simulated cameras; the V4L2 suite binds it to
the kernel's vivid devices inside the test VM.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable

import numpy as np
import pytest

from rigctl.errors import DeviceError
from rigctl.interfaces import Camera, CaptureFormat, FrameFlags

MakeCamera = Callable[[], tuple[Camera, CaptureFormat]]


def _stream(cam: Camera, fmt: CaptureFormat, n: int, timeout_s: float = 2.0) -> list:  # type: ignore[type-arg]
    cam.open()
    try:
        got = cam.configure(fmt)
        assert (got.width, got.height, got.pixel_format) == (fmt.width, fmt.height, fmt.pixel_format)
        cam.start()
        frames = []
        buf = bytearray(got.bytes_per_frame)
        for _ in range(n):
            f = cam.read(timeout_s, memoryview(buf))
            assert f is not None, "no frame within the timeout"
            frames.append((f.sequence, f.capture_ns, f.host_ns, f.flags, len(f.data), bytes(f.data[:64])))
        cam.stop()
        return frames
    finally:
        cam.close()


def check_lifecycle_is_enforced(make_camera: MakeCamera) -> None:
    """Calls out of order are refused with a DeviceError naming the device; stop and close are idempotent."""
    cam, fmt = make_camera()
    assert isinstance(cam.name, str) and cam.name
    with pytest.raises(DeviceError, match="not streaming"):
        cam.read(0.1)
    with pytest.raises(DeviceError, match="before open"):
        cam.configure(fmt)
    cam.open()
    try:
        with pytest.raises(DeviceError, match="before configure"):
            cam.start()
        with pytest.raises(DeviceError, match="not streaming"):
            cam.read(0.1)
        cam.configure(fmt)
        cam.start()
        with pytest.raises(DeviceError, match="while streaming"):
            cam.configure(fmt)
        assert cam.read(2.0) is not None
        cam.stop()
        cam.stop()  # harmless when already stopped
        with pytest.raises(DeviceError, match="not streaming"):
            cam.read(0.1)
        assert cam.status().measured_fps == 0.0, "a stopped camera reports no rate"
    finally:
        cam.close()
    cam.close()  # harmless when already closed
    cam.open()  # and the device can be opened again
    cam.close()


def check_frames_in_order_with_monotonic_timestamps(make_camera: MakeCamera) -> None:
    cam, fmt = make_camera()
    frames = _stream(cam, fmt, 16)
    seqs = [f[0] for f in frames]
    caps = [f[1] for f in frames]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs), f"sequence not strictly increasing: {seqs}"
    assert all(b > a for a, b in itertools.pairwise(caps)), "capture timestamps not increasing"
    # vivid stamps end-of-frame times up to most of a period ahead of the host's clock at DQBUF
    assert all(host >= cap - 1e9 / fmt.fps for _, cap, host, *_ in frames), "host time long before capture"
    assert all(f[4] == fmt.bytes_per_frame for f in frames), "frame size differs from the format"
    assert all(f[3] & FrameFlags.TIMESTAMP_MONOTONIC for f in frames), "timestamps not on the monotonic clock"
    now = time.monotonic_ns()
    assert -1e9 / fmt.fps < now - caps[-1] < 5e9, "capture timestamps are not on CLOCK_MONOTONIC"
    period = 1e9 / fmt.fps
    # the rate over the stream after its first few frames (drivers settle after STREAMON)
    rate = (caps[-1] - caps[4]) / (seqs[-1] - seqs[4])
    assert rate == pytest.approx(period, rel=0.15), (
        f"frame interval {rate / 1e6:.1f} ms, format says {period / 1e6:.1f}"
    )


def check_read_into_fills_the_given_buffer(make_camera: MakeCamera) -> None:
    cam, fmt = make_camera()
    cam.open()
    try:
        cam.configure(fmt)
        cam.start()
        buf = bytearray(fmt.bytes_per_frame)
        f = cam.read(2.0, memoryview(buf))
        assert f is not None
        assert np.shares_memory(np.frombuffer(f.data, np.uint8), np.frombuffer(buf, np.uint8))
        assert any(buf), "buffer left empty"
        with pytest.raises(DeviceError, match="buffer"):
            cam.read(2.0, memoryview(bytearray(16)))
    finally:
        cam.close()


def check_unsupported_format_names_what_is_offered(make_camera: MakeCamera) -> None:
    cam, fmt = make_camera()
    cam.open()
    try:
        bad = CaptureFormat(fmt.width + 2, fmt.height, fmt.pixel_format, fmt.fps)
        with pytest.raises(DeviceError, match=r"not offered.*offered"):
            cam.configure(bad)
    finally:
        cam.close()


def check_busy_when_opened_twice(make_camera: MakeCamera) -> None:
    cam, _ = make_camera()
    other, _ = make_camera()
    cam.open()
    try:
        with pytest.raises(DeviceError, match="busy"):
            other.open()
    finally:
        cam.close()
    other.open()  # free again once closed
    other.close()


def check_status_reports_signal_and_rate(make_camera: MakeCamera) -> None:
    cam, fmt = make_camera()
    cam.open()
    try:
        cam.configure(fmt)
        cam.start()
        for _ in range(15):
            assert cam.read(2.0) is not None
        st = cam.status()
        assert st.signal_present
        assert st.format is not None and (st.format.width, st.format.height) == (fmt.width, fmt.height)
        assert st.measured_fps == pytest.approx(fmt.fps, rel=0.25)
        assert st.frames >= 15
    finally:
        cam.close()


def check_restart_begins_a_new_sequence(make_camera: MakeCamera) -> None:
    cam, fmt = make_camera()
    cam.open()
    try:
        cam.configure(fmt)
        cam.start()
        first = [cam.read(2.0) for _ in range(3)]
        cam.stop()
        cam.start()
        again = cam.read(2.0)
        assert first[0] is not None and again is not None
        assert again.sequence <= 2, "sequence numbers restart at 0 on every start (V4L2 STREAMON)"
        assert again.capture_ns > first[-1].capture_ns  # type: ignore[union-attr]
    finally:
        cam.close()


CONTRACT = [
    check_lifecycle_is_enforced,
    check_frames_in_order_with_monotonic_timestamps,
    check_read_into_fills_the_given_buffer,
    check_unsupported_format_names_what_is_offered,
    check_busy_when_opened_twice,
    check_status_reports_signal_and_rate,
    check_restart_begins_a_new_sequence,
]
