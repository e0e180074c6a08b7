"""Kernel UAPI structs of ``linux/videodev2.h`` (Linux x86_64 / aarch64, 64-bit), as ctypes.

Sizes are asserted at import: a layout mistake fails loudly instead of corrupting an ioctl.
"""

from __future__ import annotations

import ctypes as C

u8, u32, s32, u64 = C.c_uint8, C.c_uint32, C.c_int32, C.c_uint64


def fourcc(code: str) -> int:
    a, b, c, d = (ord(ch) for ch in code)
    return a | (b << 8) | (c << 16) | (d << 24)


def fourcc_str(value: int) -> str:
    return "".join(chr((value >> (8 * i)) & 0xFF) for i in range(4))


class v4l2_capability(C.Structure):
    _fields_ = [
        ("driver", u8 * 16),
        ("card", u8 * 32),
        ("bus_info", u8 * 32),
        ("version", u32),
        ("capabilities", u32),
        ("device_caps", u32),
        ("reserved", u32 * 3),
    ]


class v4l2_fmtdesc(C.Structure):
    _fields_ = [
        ("index", u32),
        ("type", u32),
        ("flags", u32),
        ("description", u8 * 32),
        ("pixelformat", u32),
        ("mbus_code", u32),
        ("reserved", u32 * 3),
    ]


class v4l2_pix_format(C.Structure):
    _fields_ = [
        ("width", u32),
        ("height", u32),
        ("pixelformat", u32),
        ("field", u32),
        ("bytesperline", u32),
        ("sizeimage", u32),
        ("colorspace", u32),
        ("priv", u32),
        ("flags", u32),
        ("ycbcr_enc", u32),
        ("quantization", u32),
        ("xfer_func", u32),
    ]


class _fmt_union(C.Union):
    # raw_data is 200 bytes; the kernel's union also holds structs with pointers, so it is 8-aligned
    _fields_ = [("pix", v4l2_pix_format), ("raw_data", u8 * 200), ("_align", u64)]


class v4l2_format(C.Structure):
    _fields_ = [("type", u32), ("fmt", _fmt_union)]


class v4l2_requestbuffers(C.Structure):
    _fields_ = [
        ("count", u32),
        ("type", u32),
        ("memory", u32),
        ("capabilities", u32),
        ("flags", u8),
        ("reserved", u8 * 3),
    ]


class timeval(C.Structure):
    _fields_ = [("tv_sec", C.c_long), ("tv_usec", C.c_long)]


class v4l2_timecode(C.Structure):
    _fields_ = [
        ("type", u32),
        ("flags", u32),
        ("frames", u8),
        ("seconds", u8),
        ("minutes", u8),
        ("hours", u8),
        ("userbits", u8 * 4),
    ]


class _buf_m(C.Union):
    _fields_ = [("offset", u32), ("userptr", C.c_ulong), ("planes", C.c_void_p), ("fd", s32)]


class v4l2_buffer(C.Structure):
    _fields_ = [
        ("index", u32),
        ("type", u32),
        ("bytesused", u32),
        ("flags", u32),
        ("field", u32),
        ("timestamp", timeval),
        ("timecode", v4l2_timecode),
        ("sequence", u32),
        ("memory", u32),
        ("m", _buf_m),
        ("length", u32),
        ("reserved2", u32),
        ("request_fd", s32),
    ]


class v4l2_fract(C.Structure):
    _fields_ = [("numerator", u32), ("denominator", u32)]


class v4l2_captureparm(C.Structure):
    _fields_ = [
        ("capability", u32),
        ("capturemode", u32),
        ("timeperframe", v4l2_fract),
        ("extendedmode", u32),
        ("readbuffers", u32),
        ("reserved", u32 * 4),
    ]


class _parm_union(C.Union):
    _fields_ = [("capture", v4l2_captureparm), ("raw_data", u8 * 200)]


class v4l2_streamparm(C.Structure):
    _fields_ = [("type", u32), ("parm", _parm_union)]


class v4l2_frmsize_discrete(C.Structure):
    _fields_ = [("width", u32), ("height", u32)]


class v4l2_frmsize_stepwise(C.Structure):
    _fields_ = [
        ("min_width", u32),
        ("max_width", u32),
        ("step_width", u32),
        ("min_height", u32),
        ("max_height", u32),
        ("step_height", u32),
    ]


class _frmsize_union(C.Union):
    _fields_ = [("discrete", v4l2_frmsize_discrete), ("stepwise", v4l2_frmsize_stepwise)]


class v4l2_frmsizeenum(C.Structure):
    _anonymous_ = ("u",)
    _fields_ = [("index", u32), ("pixel_format", u32), ("type", u32), ("u", _frmsize_union), ("reserved", u32 * 2)]


class v4l2_frmival_stepwise(C.Structure):
    _fields_ = [("min", v4l2_fract), ("max", v4l2_fract), ("step", v4l2_fract)]


class _frmival_union(C.Union):
    _fields_ = [("discrete", v4l2_fract), ("stepwise", v4l2_frmival_stepwise)]


class v4l2_frmivalenum(C.Structure):
    _anonymous_ = ("u",)
    _fields_ = [
        ("index", u32),
        ("pixel_format", u32),
        ("width", u32),
        ("height", u32),
        ("type", u32),
        ("u", _frmival_union),
        ("reserved", u32 * 2),
    ]


class v4l2_bt_timings(C.Structure):
    _pack_ = 1
    _fields_ = [
        ("width", u32),
        ("height", u32),
        ("interlaced", u32),
        ("polarities", u32),
        ("pixelclock", u64),
        ("hfrontporch", u32),
        ("hsync", u32),
        ("hbackporch", u32),
        ("vfrontporch", u32),
        ("vsync", u32),
        ("vbackporch", u32),
        ("il_vfrontporch", u32),
        ("il_vsync", u32),
        ("il_vbackporch", u32),
        ("standards", u32),
        ("flags", u32),
        ("picture_aspect", v4l2_fract),
        ("cea861_vic", u8),
        ("hdmi_vic", u8),
        ("reserved", u8 * 46),
    ]


class _dv_union(C.Union):
    _pack_ = 1
    _fields_ = [("bt", v4l2_bt_timings), ("reserved", u32 * 32)]


class v4l2_dv_timings(C.Structure):
    _pack_ = 1
    _fields_ = [("type", u32), ("u", _dv_union)]


class v4l2_enum_dv_timings(C.Structure):
    _fields_ = [("index", u32), ("pad", u32), ("reserved", u32 * 2), ("timings", v4l2_dv_timings)]


class v4l2_input(C.Structure):
    _fields_ = [
        ("index", u32),
        ("name", u8 * 32),
        ("type", u32),
        ("audioset", u32),
        ("tuner", u32),
        ("std", u64),
        ("status", u32),
        ("capabilities", u32),
        ("reserved", u32 * 3),
    ]


SIZES = {
    v4l2_capability: 104,
    v4l2_fmtdesc: 64,
    v4l2_format: 208,
    v4l2_requestbuffers: 20,
    v4l2_buffer: 88,
    v4l2_streamparm: 204,
    v4l2_frmsizeenum: 44,
    v4l2_frmivalenum: 52,
    v4l2_dv_timings: 132,
    v4l2_enum_dv_timings: 148,
    v4l2_input: 80,
    v4l2_timecode: 16,
}
for _cls, _size in SIZES.items():
    if C.sizeof(_cls) != _size:  # pragma: no cover - a build for another ABI
        raise ImportError(f"{_cls.__name__} is {C.sizeof(_cls)} bytes, the kernel's is {_size}: unsupported ABI")

# enums and flags
BUF_TYPE_VIDEO_CAPTURE = 1
MEMORY_MMAP = 1
FIELD_ANY, FIELD_NONE = 0, 1
CAP_VIDEO_CAPTURE = 0x00000001
CAP_STREAMING = 0x04000000
CAP_DEVICE_CAPS = 0x80000000
CAP_TIMEPERFRAME = 0x1000
BUF_FLAG_ERROR = 0x00000040
BUF_FLAG_TIMECODE = 0x00000100
# struct v4l2_timecode: type gives the nominal rate, flags the drop-frame counting (videodev2.h)
TC_TYPE_RATES = {1: 24, 2: 25, 3: 30, 4: 50, 5: 60}  # V4L2_TC_TYPE_24FPS .. V4L2_TC_TYPE_60FPS
TC_FLAG_DROPFRAME = 0x0001
BUF_FLAG_TIMESTAMP_MASK = 0x0000E000
BUF_FLAG_TIMESTAMP_MONOTONIC = 0x00002000
BUF_FLAG_TSTAMP_SRC_MASK = 0x00070000
BUF_FLAG_TSTAMP_SRC_SOE = 0x00010000
FRMSIZE_TYPE_DISCRETE, FRMSIZE_TYPE_CONTINUOUS, FRMSIZE_TYPE_STEPWISE = 1, 2, 3
DV_BT_656_1120 = 0
IN_CAP_DV_TIMINGS = 0x00000002
IN_ST_NO_POWER = 0x00000001
IN_ST_NO_SIGNAL = 0x00000002
