"""One small function per V4L2 ioctl, each taking a file descriptor (ioctl numbers from the struct sizes)."""

from __future__ import annotations

import ctypes as C
import fcntl

from rigctl.drivers.v4l2 import structs as S

_NONE, _WRITE, _READ = 0, 1, 2


def _ioc(direction: int, nr: int, size: int) -> int:
    return (direction << 30) | (size << 16) | (ord("V") << 8) | nr


def _IOR(nr: int, t: type) -> int:
    return _ioc(_READ, nr, C.sizeof(t))


def _IOW(nr: int, t: type) -> int:
    return _ioc(_WRITE, nr, C.sizeof(t))


def _IOWR(nr: int, t: type) -> int:
    return _ioc(_READ | _WRITE, nr, C.sizeof(t))


QUERYCAP = _IOR(0, S.v4l2_capability)
ENUM_FMT = _IOWR(2, S.v4l2_fmtdesc)
G_FMT = _IOWR(4, S.v4l2_format)
S_FMT = _IOWR(5, S.v4l2_format)
REQBUFS = _IOWR(8, S.v4l2_requestbuffers)
QUERYBUF = _IOWR(9, S.v4l2_buffer)
QBUF = _IOWR(15, S.v4l2_buffer)
DQBUF = _IOWR(17, S.v4l2_buffer)
STREAMON = _IOW(18, C.c_int)
STREAMOFF = _IOW(19, C.c_int)
G_PARM = _IOWR(21, S.v4l2_streamparm)
S_PARM = _IOWR(22, S.v4l2_streamparm)
ENUMINPUT = _IOWR(26, S.v4l2_input)
G_INPUT = _IOR(38, C.c_int)
S_INPUT = _IOWR(39, C.c_int)
TRY_FMT = _IOWR(64, S.v4l2_format)
ENUM_FRAMESIZES = _IOWR(74, S.v4l2_frmsizeenum)
ENUM_FRAMEINTERVALS = _IOWR(75, S.v4l2_frmivalenum)
S_DV_TIMINGS = _IOWR(87, S.v4l2_dv_timings)
G_DV_TIMINGS = _IOWR(88, S.v4l2_dv_timings)
ENUM_DV_TIMINGS = _IOWR(98, S.v4l2_enum_dv_timings)
QUERY_DV_TIMINGS = _IOR(99, S.v4l2_dv_timings)


def _call(fd: int, request: int, arg: C.Structure | C.c_int) -> None:
    fcntl.ioctl(fd, request, arg, True)


def querycap(fd: int) -> S.v4l2_capability:
    cap = S.v4l2_capability()
    _call(fd, QUERYCAP, cap)
    return cap


def enum_fmt(fd: int, index: int) -> S.v4l2_fmtdesc:
    d = S.v4l2_fmtdesc(index=index, type=S.BUF_TYPE_VIDEO_CAPTURE)
    _call(fd, ENUM_FMT, d)
    return d


def g_fmt(fd: int) -> S.v4l2_format:
    f = S.v4l2_format(type=S.BUF_TYPE_VIDEO_CAPTURE)
    _call(fd, G_FMT, f)
    return f


def s_fmt(fd: int, fmt: S.v4l2_format) -> S.v4l2_format:
    _call(fd, S_FMT, fmt)
    return fmt


def try_fmt(fd: int, fmt: S.v4l2_format) -> S.v4l2_format:
    _call(fd, TRY_FMT, fmt)
    return fmt


def reqbufs(fd: int, count: int) -> int:
    r = S.v4l2_requestbuffers(count=count, type=S.BUF_TYPE_VIDEO_CAPTURE, memory=S.MEMORY_MMAP)
    _call(fd, REQBUFS, r)
    return int(r.count)


def querybuf(fd: int, index: int) -> S.v4l2_buffer:
    b = S.v4l2_buffer(index=index, type=S.BUF_TYPE_VIDEO_CAPTURE, memory=S.MEMORY_MMAP)
    _call(fd, QUERYBUF, b)
    return b


def qbuf(fd: int, buf: S.v4l2_buffer) -> None:
    _call(fd, QBUF, buf)


def dqbuf(fd: int, buf: S.v4l2_buffer) -> None:
    """Dequeue into ``buf`` (reused: no allocation per frame)."""
    buf.type = S.BUF_TYPE_VIDEO_CAPTURE
    buf.memory = S.MEMORY_MMAP
    _call(fd, DQBUF, buf)


def streamon(fd: int) -> None:
    _call(fd, STREAMON, C.c_int(S.BUF_TYPE_VIDEO_CAPTURE))


def streamoff(fd: int) -> None:
    _call(fd, STREAMOFF, C.c_int(S.BUF_TYPE_VIDEO_CAPTURE))


def g_parm(fd: int) -> S.v4l2_streamparm:
    p = S.v4l2_streamparm(type=S.BUF_TYPE_VIDEO_CAPTURE)
    _call(fd, G_PARM, p)
    return p


def s_parm(fd: int, numerator: int, denominator: int) -> S.v4l2_streamparm:
    p = S.v4l2_streamparm(type=S.BUF_TYPE_VIDEO_CAPTURE)
    p.parm.capture.timeperframe.numerator = numerator
    p.parm.capture.timeperframe.denominator = denominator
    _call(fd, S_PARM, p)
    return p


def enum_framesizes(fd: int, pixelformat: int, index: int) -> S.v4l2_frmsizeenum:
    f = S.v4l2_frmsizeenum(index=index, pixel_format=pixelformat)
    _call(fd, ENUM_FRAMESIZES, f)
    return f


def enum_frameintervals(fd: int, pixelformat: int, width: int, height: int, index: int) -> S.v4l2_frmivalenum:
    f = S.v4l2_frmivalenum(index=index, pixel_format=pixelformat, width=width, height=height)
    _call(fd, ENUM_FRAMEINTERVALS, f)
    return f


def query_dv_timings(fd: int) -> S.v4l2_dv_timings:
    t = S.v4l2_dv_timings()
    _call(fd, QUERY_DV_TIMINGS, t)
    return t


def g_dv_timings(fd: int) -> S.v4l2_dv_timings:
    t = S.v4l2_dv_timings()
    _call(fd, G_DV_TIMINGS, t)
    return t


def s_dv_timings(fd: int, timings: S.v4l2_dv_timings) -> None:
    _call(fd, S_DV_TIMINGS, timings)


def enum_dv_timings(fd: int, index: int) -> S.v4l2_enum_dv_timings:
    e = S.v4l2_enum_dv_timings(index=index)
    _call(fd, ENUM_DV_TIMINGS, e)
    return e


def enuminput(fd: int, index: int) -> S.v4l2_input:
    i = S.v4l2_input(index=index)
    _call(fd, ENUMINPUT, i)
    return i


def g_input(fd: int) -> int:
    v = C.c_int()
    _call(fd, G_INPUT, v)
    return int(v.value)


def s_input(fd: int, index: int) -> None:
    _call(fd, S_INPUT, C.c_int(index))
