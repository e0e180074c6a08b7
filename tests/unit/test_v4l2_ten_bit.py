"""The V4L2 camera negotiates 10-bit 4:2:2 (Y210, v210) like any fourcc, and checks the driver's frame size
against the layout: Y210 four bytes a pixel, v210 its 128-byte lines (a fake device: the logic only; the
kernel's vivid, the VM test bed's device, offers no 10-bit 4:2:2 format)."""

from __future__ import annotations

import pytest
from rigctl.drivers.v4l2 import structs as S
from rigctl.drivers.v4l2.camera import V4L2Camera

from rigctl.errors import DeviceError
from rigctl.interfaces import CaptureFormat
from rigctl.yuv10 import device_frame_bytes


class FakeDevice:
    """A capture node with no DV timings offering ``formats``, whose driver reports ``sizeimage``."""

    def __init__(self, formats: list[str], sizeimage: dict[str, int]) -> None:
        self.formats, self.sizeimage = formats, sizeimage
        self.fmt = (0, 0, "", 0)

    def has_dv_timings(self) -> bool:
        return False

    def set_format(self, width: int, height: int, fourcc: str) -> tuple[int, int, str, int]:
        if fourcc not in self.formats:
            raise DeviceError(f"fake: pixel format {fourcc} not offered (offered: {', '.join(self.formats)})")
        self.fmt = (width, height, fourcc, self.sizeimage[fourcc])
        return self.fmt

    def set_rate(self, fps: float) -> float:
        return fps

    def get_format(self) -> tuple[int, int, str, int]:
        return self.fmt


def _camera(device: FakeDevice) -> V4L2Camera:
    cam = V4L2Camera("r0c0", "v4l2:///dev/video0")
    cam.device = device  # type: ignore[assignment]
    return cam


def test_the_fourccs_are_the_kernels() -> None:
    assert S.fourcc("Y210") == ord("Y") | ord("2") << 8 | ord("1") << 16 | ord("0") << 24  # V4L2_PIX_FMT_Y210
    assert S.fourcc_str(S.fourcc("v210")) == "v210"


@pytest.mark.parametrize("fourcc", ["Y210", "v210"])
def test_a_device_offering_ten_bit_four_two_two_is_configured_for_it(fourcc: str) -> None:
    size = device_frame_bytes(fourcc, 1280, 720)
    cam = _camera(FakeDevice(["UYVY", "Y210", "v210"], {"UYVY": 1280 * 720 * 2, "Y210": size, "v210": size}))
    got = cam._do_configure(CaptureFormat(1280, 720, fourcc, 25))
    assert got == CaptureFormat(1280, 720, fourcc, 25)
    assert got.bytes_per_frame == size  # v210: 1280 px is 27 blocks of 48 px, 3456 bytes a line
    assert got.stored_bytes_per_frame == 1280 * 720 * 20 // 8


def test_a_driver_frame_too_small_for_the_layout_is_refused() -> None:
    cam = _camera(FakeDevice(["v210"], {"v210": 1280 * 720 * 8 // 3}))  # no line padding: short of 3456 a line
    with pytest.raises(DeviceError, match="needs more"):
        cam._do_configure(CaptureFormat(1280, 720, "v210", 25))


def test_a_device_without_ten_bit_says_what_it_offers() -> None:
    cam = _camera(FakeDevice(["UYVY", "YUYV"], {"UYVY": 1920 * 1080 * 2}))
    with pytest.raises(DeviceError, match=r"Y210 not offered \(offered: UYVY, YUYV\)"):
        cam._do_configure(CaptureFormat(1920, 1080, "Y210", 25))
