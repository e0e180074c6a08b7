"""The ctypes layer matches the kernel's ABI: struct sizes and ioctl request numbers (checked against a C
program built with linux/videodev2.h on x86_64; a wrong size changes the number and the kernel answers
ENOTTY)."""

from __future__ import annotations

import ctypes

import pytest
from rigctl.drivers.v4l2 import ioctls as I
from rigctl.drivers.v4l2 import structs as S
from rigctl.drivers.v4l2.device import resolve_address

from rigctl.errors import DeviceError


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("QUERYCAP", 0x80685600),
        ("ENUM_FMT", 0xC0405602),
        ("G_FMT", 0xC0D05604),
        ("S_FMT", 0xC0D05605),
        ("REQBUFS", 0xC0145608),
        ("QUERYBUF", 0xC0585609),
        ("QBUF", 0xC058560F),
        ("DQBUF", 0xC0585611),
        ("STREAMON", 0x40045612),
        ("STREAMOFF", 0x40045613),
        ("G_PARM", 0xC0CC5615),
        ("S_PARM", 0xC0CC5616),
        ("ENUMINPUT", 0xC050561A),
        ("G_INPUT", 0x80045626),
        ("S_INPUT", 0xC0045627),
        ("TRY_FMT", 0xC0D05640),
        ("ENUM_FRAMESIZES", 0xC02C564A),
        ("ENUM_FRAMEINTERVALS", 0xC034564B),
        ("S_DV_TIMINGS", 0xC0845657),
        ("G_DV_TIMINGS", 0xC0845658),
        ("ENUM_DV_TIMINGS", 0xC0945662),
        ("QUERY_DV_TIMINGS", 0x80845663),
    ],
)
def test_request_numbers(name: str, value: int) -> None:
    assert getattr(I, name) == value


def test_buffer_field_offsets() -> None:
    assert S.v4l2_buffer.timestamp.offset == 24
    assert S.v4l2_buffer.sequence.offset == 56
    assert S.v4l2_buffer.m.offset == 64
    assert S.v4l2_format.fmt.offset == 8
    assert ctypes.sizeof(S.v4l2_bt_timings) == 124


def test_fourcc_round_trip() -> None:
    assert S.fourcc("UYVY") == 0x59565955
    assert S.fourcc_str(S.fourcc("BGR3")) == "BGR3"


def test_addresses() -> None:
    assert str(resolve_address("v4l2:///dev/video3")) == "/dev/video3"
    assert str(resolve_address("/dev/v4l/by-path/pci-0000:03:00.0-video-index0")).startswith("/dev/v4l/by-path/")
    with pytest.raises(DeviceError, match="not a V4L2 device address"):
        resolve_address("v4l2://video3")
