"""A V4L2 capture device: capabilities, formats, DV timings, and memory-mapped streaming.

The device owns its file descriptor and its mmap'ed driver buffers; frames are copied out into the
caller's preallocated buffer and the driver buffer goes straight back to the queue, so nothing is
allocated per frame and the driver never runs out of buffers because a consumer held on to one.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import mmap
import os
import select
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from rigctl.drivers.v4l2 import ioctls as I
from rigctl.drivers.v4l2 import structs as S

from rigctl.errors import DeviceError
from rigctl.timecode import Timecode, rate_of


def resolve_address(address: str) -> Path:
    """``v4l2:///dev/video0``, ``/dev/video0``, ``/dev/v4l/by-path/...`` or ``/dev/v4l/by-id/...`` -> path."""
    path = address.removeprefix("v4l2://")
    if not path.startswith("/dev/"):
        raise DeviceError(f"{address}: not a V4L2 device address (v4l2:///dev/videoN or /dev/v4l/by-...)")
    return Path(path)


def _text(raw: object) -> str:
    return bytes(raw).split(b"\0", 1)[0].decode("utf-8", "replace")  # type: ignore[call-overload]


@dataclass(frozen=True)
class DvTimings:
    width: int
    height: int
    fps: float
    interlaced: bool
    pixelclock: int

    def describe(self) -> str:
        return f"{self.width}x{self.height}{'i' if self.interlaced else 'p'}{self.fps:.2f}"


def _dv(t: S.v4l2_dv_timings) -> DvTimings:
    bt = t.u.bt
    total_w = bt.width + bt.hfrontporch + bt.hsync + bt.hbackporch
    total_h = bt.height + bt.vfrontporch + bt.vsync + bt.vbackporch
    if bt.interlaced:
        total_h += bt.il_vfrontporch + bt.il_vsync + bt.il_vbackporch
    fps = bt.pixelclock / (total_w * total_h) if total_w and total_h else 0.0
    return DvTimings(int(bt.width), int(bt.height), float(fps), bool(bt.interlaced), int(bt.pixelclock))


@dataclass(frozen=True)
class Dequeued:
    """What the driver reported about one frame."""

    sequence: int
    timestamp_ns: int
    flags: int
    size: int
    timecode: KernelTimecode | None


class KernelTimecode(NamedTuple):
    """The fields of the kernel's struct v4l2_timecode, as integers."""

    type: int
    flags: int
    hours: int
    minutes: int
    seconds: int
    frames: int

    def to_timecode(self, fps: float) -> Timecode:
        """The value of this label: rate from ``type`` (else the format's ``fps``), drop-frame from ``flags``.
        Raises TimecodeError for a label that does not exist at that rate."""
        rate = S.TC_TYPE_RATES.get(self.type) or rate_of(fps)[0]
        drop = bool(self.flags & S.TC_FLAG_DROPFRAME)
        return Timecode.from_fields(self.hours, self.minutes, self.seconds, self.frames, rate, drop)


class V4L2Device:
    """One ``/dev/videoN`` opened for capture. Use as a context manager."""

    def __init__(self, address: str) -> None:
        self.address = address
        self.path = resolve_address(address)
        self.fd = -1
        self._maps: list[mmap.mmap] = []
        self._views: list[memoryview] = []
        self._buf = S.v4l2_buffer()
        self.streaming = False

    # ---- lifecycle ---------------------------------------------------------------------------------
    def open(self) -> None:
        if not self.path.exists():
            raise DeviceError(f"{self.address}: no such device (is the capture card present and its driver loaded?)")
        try:
            self.fd = os.open(self.path, os.O_RDWR | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        except PermissionError:
            raise DeviceError(f"{self.address}: permission denied (add the user to the 'video' group)") from None
        except OSError as exc:
            raise DeviceError(f"{self.address}: cannot open: {exc.strerror}") from None
        try:
            # V4L2 lets many processes open a node; an advisory lock keeps two rigctl processes apart, and a
            # foreign process that streams makes S_FMT/REQBUFS fail with EBUSY, reported as busy too.
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.close()
            raise DeviceError(f"{self.address}: device is busy (another rigctl process has it open)") from None
        cap = self.capability()
        caps = cap.device_caps if cap.capabilities & S.CAP_DEVICE_CAPS else cap.capabilities
        if not caps & S.CAP_VIDEO_CAPTURE or not caps & S.CAP_STREAMING:
            self.close()
            raise DeviceError(f"{self.address}: not a streaming video capture device ({_text(cap.card)})")

    def close(self) -> None:
        if self.streaming:
            with contextlib.suppress(DeviceError):
                self.stop()
        self._unmap()
        if self.fd >= 0:
            os.close(self.fd)
        self.fd = -1

    def __enter__(self) -> V4L2Device:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _fail(self, what: str, exc: OSError) -> DeviceError:
        if exc.errno == errno.EBUSY:
            return DeviceError(f"{self.address}: device is busy ({what}: another process is streaming from it)")
        if exc.errno in (errno.ENODEV, errno.ENXIO, errno.EIO):
            return DeviceError(f"{self.address}: device disappeared ({what}: {exc.strerror})")
        return DeviceError(f"{self.address}: {what} failed: {exc.strerror}")

    # ---- what the device is and offers -------------------------------------------------------------
    def capability(self) -> S.v4l2_capability:
        try:
            return I.querycap(self.fd)
        except OSError as exc:
            raise self._fail("VIDIOC_QUERYCAP", exc) from None

    def identity(self) -> dict[str, str]:
        cap = self.capability()
        return {"driver": _text(cap.driver), "card": _text(cap.card), "bus": _text(cap.bus_info)}

    def formats(self) -> list[str]:
        out = []
        for i in range(256):
            try:
                out.append(S.fourcc_str(I.enum_fmt(self.fd, i).pixelformat))
            except OSError:
                break
        return out

    def frame_sizes(self, fourcc: str) -> list[tuple[int, int]] | tuple[int, int, int, int]:
        """Discrete sizes, or (min w, max w, min h, max h) for a stepwise or continuous range."""
        sizes: list[tuple[int, int]] = []
        for i in range(256):
            try:
                f = I.enum_framesizes(self.fd, S.fourcc(fourcc), i)
            except OSError:
                break
            if f.type == S.FRMSIZE_TYPE_DISCRETE:
                sizes.append((int(f.discrete.width), int(f.discrete.height)))
            else:
                sw = f.stepwise
                return int(sw.min_width), int(sw.max_width), int(sw.min_height), int(sw.max_height)
        return sizes

    def frame_rates(self, fourcc: str, width: int, height: int) -> list[float]:
        rates = []
        for i in range(64):
            try:
                f = I.enum_frameintervals(self.fd, S.fourcc(fourcc), width, height, i)
            except OSError:
                break
            if f.type == S.FRMSIZE_TYPE_DISCRETE and f.discrete.numerator:
                rates.append(f.discrete.denominator / f.discrete.numerator)
            else:
                break
        return rates

    def get_format(self) -> tuple[int, int, str, int]:
        """(width, height, fourcc, sizeimage) currently set."""
        try:
            f = I.g_fmt(self.fd)
        except OSError as exc:
            raise self._fail("VIDIOC_G_FMT", exc) from None
        p = f.fmt.pix
        return int(p.width), int(p.height), S.fourcc_str(p.pixelformat), int(p.sizeimage)

    def set_format(self, width: int, height: int, fourcc: str) -> tuple[int, int, str, int]:
        """Set and read back; refuses (naming what is offered) when the driver adjusts the request."""
        offered = self.formats()
        if fourcc not in offered:
            raise DeviceError(f"{self.address}: pixel format {fourcc} not offered (offered: {', '.join(offered)})")
        f = S.v4l2_format(type=S.BUF_TYPE_VIDEO_CAPTURE)
        f.fmt.pix.width, f.fmt.pix.height = width, height
        f.fmt.pix.pixelformat = S.fourcc(fourcc)
        f.fmt.pix.field = S.FIELD_NONE
        try:
            I.s_fmt(self.fd, f)
        except OSError as exc:
            raise self._fail("VIDIOC_S_FMT", exc) from None
        got = self.get_format()
        if got[:3] != (width, height, fourcc):
            sizes = self.frame_sizes(fourcc)
            raise DeviceError(
                f"{self.address}: format {width}x{height} {fourcc} not offered: the driver gives "
                f"{got[0]}x{got[1]} {got[2]} (offered sizes: {sizes or 'set by the input signal'})"
            )
        return got

    def get_rate(self) -> float:
        try:
            p = I.g_parm(self.fd)
        except OSError:
            return 0.0
        tpf = p.parm.capture.timeperframe
        return tpf.denominator / tpf.numerator if tpf.numerator else 0.0

    def set_rate(self, fps: float) -> float:
        """Ask for ``fps`` (as a fraction, 30000/1001 for 29.97) and return what the driver set."""
        num, den = (
            (1001, round(fps * 1001)) if abs(fps * 1001 - round(fps * 1001)) < 1e-3 and fps % 1 else (1, round(fps))
        )
        try:
            p = I.s_parm(self.fd, num, den)
        except OSError as exc:
            raise self._fail("VIDIOC_S_PARM", exc) from None
        tpf = p.parm.capture.timeperframe
        return tpf.denominator / tpf.numerator if tpf.numerator else 0.0

    def has_dv_timings(self) -> bool:
        try:
            inp = I.enuminput(self.fd, I.g_input(self.fd))
        except OSError:
            return False
        return bool(inp.capabilities & S.IN_CAP_DV_TIMINGS)

    def input_status(self) -> int:
        """The current input's status bits (V4L2_IN_ST_*), 0 when all is well."""
        try:
            return int(I.enuminput(self.fd, I.g_input(self.fd)).status)
        except OSError:
            return 0

    def query_dv_timings(self) -> DvTimings | None:
        """What the input receives, or None with no signal (ENOLINK) or an unstable one (ENOLCK)."""
        try:
            return _dv(I.query_dv_timings(self.fd))
        except OSError as exc:
            if exc.errno in (errno.ENOLINK, errno.ENOLCK, errno.ERANGE):
                return None
            raise self._fail("VIDIOC_QUERY_DV_TIMINGS", exc) from None

    def dv_timings(self) -> DvTimings:
        try:
            return _dv(I.g_dv_timings(self.fd))
        except OSError as exc:
            raise self._fail("VIDIOC_G_DV_TIMINGS", exc) from None

    def dv_timings_offered(self) -> list[DvTimings]:
        out = []
        for i in range(128):
            try:
                out.append(_dv(I.enum_dv_timings(self.fd, i).timings))
            except OSError:
                break
        return out

    def set_dv_timings(self, width: int, height: int, fps: float) -> DvTimings:
        """Choose the input's DV timings (SDI/HDMI inputs: the format follows them)."""
        for i in range(128):
            try:
                e = I.enum_dv_timings(self.fd, i)
            except OSError:
                break
            t = _dv(e.timings)
            if (t.width, t.height, t.interlaced) == (width, height, False) and abs(t.fps - fps) < 0.05:
                try:
                    I.s_dv_timings(self.fd, e.timings)
                except OSError as exc:
                    raise self._fail("VIDIOC_S_DV_TIMINGS", exc) from None
                return self.dv_timings()
        offered = ", ".join(t.describe() for t in self.dv_timings_offered()) or "none"
        raise DeviceError(f"{self.address}: DV timings {width}x{height}p{fps:g} not offered (offered: {offered})")

    # ---- streaming ---------------------------------------------------------------------------------
    def start(self, buffers: int = 8) -> None:
        try:
            count = I.reqbufs(self.fd, buffers)
        except OSError as exc:
            raise self._fail("VIDIOC_REQBUFS", exc) from None
        if count < 2:
            raise DeviceError(f"{self.address}: driver granted {count} buffer(s); streaming needs at least 2")
        try:
            for i in range(count):
                b = I.querybuf(self.fd, i)
                m = mmap.mmap(self.fd, b.length, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE, offset=b.m.offset)
                self._maps.append(m)
                self._views.append(memoryview(m))
                I.qbuf(self.fd, b)
            I.streamon(self.fd)
        except OSError as exc:
            self._unmap()
            raise self._fail("starting the stream", exc) from None
        self.streaming = True

    def stop(self) -> None:
        if not self.streaming:
            return
        self.streaming = False
        try:
            I.streamoff(self.fd)
        except OSError as exc:
            if exc.errno not in (errno.ENODEV, errno.EIO):
                raise self._fail("VIDIOC_STREAMOFF", exc) from None
        finally:
            self._unmap()
            with contextlib.suppress(OSError):
                I.reqbufs(self.fd, 0)

    def _unmap(self) -> None:
        for v in self._views:
            v.release()
        for m in self._maps:
            m.close()
        self._views.clear()
        self._maps.clear()

    def dequeue(self, timeout_s: float, into: memoryview) -> Dequeued | None:
        """Wait up to ``timeout_s`` for a filled buffer, copy its bytes into ``into`` and requeue it.

        Returns what the driver said of the frame, or None on timeout.
        """
        try:
            ready, _, _ = select.select([self.fd], [], [], timeout_s)
        except OSError as exc:
            raise self._fail("waiting for a frame", exc) from None
        if not ready:
            return None
        buf = self._buf
        try:
            I.dqbuf(self.fd, buf)
        except BlockingIOError:
            return None
        except OSError as exc:
            raise self._fail("VIDIOC_DQBUF", exc) from None
        n = int(buf.bytesused)
        # read everything before QBUF: the kernel rewrites the descriptor when it takes the buffer back
        ts = buf.timestamp
        tc = buf.timecode
        got = Dequeued(
            sequence=int(buf.sequence),
            timestamp_ns=int(ts.tv_sec) * 1_000_000_000 + int(ts.tv_usec) * 1000,
            flags=int(buf.flags),
            size=n,
            timecode=KernelTimecode(
                int(tc.type), int(tc.flags), int(tc.hours), int(tc.minutes), int(tc.seconds), int(tc.frames)
            )
            if buf.flags & S.BUF_FLAG_TIMECODE
            else None,
        )
        if n > len(into):
            I.qbuf(self.fd, buf)
            raise DeviceError(f"{self.address}: frame of {n} bytes does not fit a {len(into)}-byte buffer")
        into[:n] = self._views[buf.index][:n]
        try:
            I.qbuf(self.fd, buf)
        except OSError as exc:
            raise self._fail("VIDIOC_QBUF", exc) from None
        return got
