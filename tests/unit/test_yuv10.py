"""10-bit 4:2:2 layouts (rigctl.yuv10): Y210 and v210 as their documents lay them out, the take's 20-bit
packing, the repacking the recorder does, and float RGB that keeps super-whites and sub-blacks."""

from __future__ import annotations

import numpy as np
import pytest

from rigctl import yuv10
from rigctl.errors import RigFileError
from rigctl.interfaces import CaptureFormat
from rigctl.pixfmt import from_rgb, rgb_to_codes10, rgb_to_uyvy, to_bgr8, to_gray8, to_rgb, uyvy_to_rgb, video_range
from rigctl.rig import load_rig, rig_from_dict


def _codes(rng: np.random.Generator, w: int, h: int) -> np.ndarray:
    return rng.integers(yuv10.FLOOR_CODE, yuv10.PEAK_CODE + 1, (h, 2 * w)).astype(np.uint16)


def test_y210_is_yuyv_in_little_endian_words_with_the_ten_bits_high() -> None:
    # one pixel pair: Cb 0x155, Y0 0x3FF, Cr 0x2AA, Y1 0x001 (codes in UYVY order)
    codes = np.array([[0x155, 0x3FF, 0x2AA, 0x001]], np.uint16)
    raw = yuv10.to_device(codes, "Y210").reshape(-1)
    words = [int.from_bytes(raw[i : i + 2].tobytes(), "little") for i in range(0, 8, 2)]
    assert words == [0x3FF << 6, 0x155 << 6, 0x001 << 6, 0x2AA << 6]  # Y0 Cb Y1 Cr
    assert raw[:2].tolist() == [0xC0, 0xFF]
    assert (yuv10.from_device(raw, "Y210", 2, 1) == codes).all()


def test_v210_puts_three_samples_in_each_word_and_pads_lines_to_128_bytes() -> None:
    codes = np.arange(1, 13, dtype=np.uint16).reshape(1, 12) * 7  # six pixels: Cb0 Y0 Cr0 Y1 Cb2 Y2 ...
    raw = yuv10.to_device(codes, "v210").reshape(-1)
    assert raw.size == 128  # one line of six pixels still takes a 48-pixel block
    w = np.frombuffer(raw.tobytes(), "<u4")
    c = codes[0].tolist()
    assert w[0] == c[0] | c[1] << 10 | c[2] << 20  # Cb0 Y0 Cr0
    assert w[1] == c[3] | c[4] << 10 | c[5] << 20  # Y1 Cb2 Y2
    assert w[3] == c[9] | c[10] << 10 | c[11] << 20  # Y4 Cr4 Y5
    assert not w[4:].any()
    assert yuv10.v210_stride(1920) == 5120 and yuv10.v210_stride(1280) == 3456


def test_the_take_packs_twenty_bits_a_pixel_most_significant_bit_first() -> None:
    codes = np.array([[0x3FF, 0x000, 0x3FF, 0x000]], np.uint16)
    assert yuv10.pack(codes).tolist() == [[0xFF, 0xC0, 0x0F, 0xFC, 0x00]]
    rng = np.random.default_rng(1)
    for w, h in ((960, 6), (1280, 3), (14, 2)):
        c = _codes(rng, w, h)
        packed = yuv10.pack(c)
        assert packed.nbytes == w * h * 20 // 8 == yuv10.essence_frame_bytes(w, h)
        assert (yuv10.unpack(packed, w, h) == c).all()


@pytest.mark.parametrize("pixel_format", ["Y210", "v210"])
def test_the_recorders_repacking_equals_decoding_then_packing(pixel_format: str) -> None:
    rng = np.random.default_rng(2)
    for w, h in ((960, 4), (1280, 3), (2, 1), (50, 2)):
        c = _codes(rng, w, h)
        device = yuv10.to_device(c, pixel_format).reshape(-1)
        assert device.nbytes == yuv10.device_frame_bytes(pixel_format, w, h)
        out = memoryview(bytearray(yuv10.essence_frame_bytes(w, h) + 7))
        got = yuv10.device_to_essence(memoryview(device), pixel_format, w, h, out)
        assert bytes(got) == yuv10.pack(c).tobytes()


def test_capture_format_sizes_the_device_frame_and_the_stored_one() -> None:
    y210 = CaptureFormat(3840, 2160, "Y210", 25)
    v210 = CaptureFormat(3840, 2160, "v210", 25)
    assert y210.bytes_per_frame == 33_177_600 and v210.bytes_per_frame == 22_118_400
    assert y210.stored_bytes_per_frame == v210.stored_bytes_per_frame == 20_736_000  # 20 bits a pixel
    assert CaptureFormat(3840, 2160, "UYVY", 25).stored_bytes_per_frame == 16_588_800  # 8-bit unchanged


def test_ten_bit_codes_are_quantised_from_float_not_eight_bit_codes_shifted() -> None:
    ramp = np.repeat(np.linspace(0.0, 1.0, 512, dtype=np.float32)[None, :, None], 3, axis=2)
    y = rgb_to_codes10(np.repeat(ramp, 2, axis=0))[:, 1::2]
    assert (y % 4 != 0).mean() > 0.7  # a quarter of 10-bit codes are multiples of 4
    assert y.min() == 64 and y.max() == 940
    back = to_rgb(from_rgb(ramp, "Y210"), "Y210", 512, 1)
    assert np.abs(back - ramp).max() < 0.6 / 876  # within half a 10-bit step (plus float rounding)


@pytest.mark.parametrize("pixel_format", ["UYVY", "Y210"])
def test_float_rgb_keeps_super_whites_and_sub_blacks_and_8_bit_outputs_clip(pixel_format: str) -> None:
    lo, hi = video_range(pixel_format)
    assert hi > 1.08 and lo < -0.06
    grey = np.array([-0.2, -0.05, 0.0, 0.5, 1.0, 1.05, 1.2, 1.2], np.float32)
    rgb = np.repeat(np.repeat(grey[None, :, None], 3, axis=2), 2, axis=0)
    data = from_rgb(np.clip(rgb, lo, hi), pixel_format).reshape(-1)
    back = to_rgb(data, pixel_format, 8, 2)[0, :, 1]
    assert back[5] == pytest.approx(1.05, abs=0.005)
    assert back[6] == pytest.approx(hi, abs=0.005)  # at the format's peak code (254 / 1019), not at 1.0
    assert back[1] == pytest.approx(-0.05, abs=0.005) and back[0] == pytest.approx(lo, abs=0.005)
    bgr = to_bgr8(data, pixel_format, 8, 2)[0, :, 1]
    assert bgr[5:].tolist() == [255, 255, 255] and bgr[:3].tolist() == [0, 0, 0]
    assert to_gray8(data, pixel_format, 8, 2)[0, 6] == 255


def test_8_bit_decoding_is_unchanged_within_the_nominal_range() -> None:
    rng = np.random.default_rng(3)
    rgb = np.repeat(rng.random((4, 8, 3), dtype=np.float32), 2, axis=1)  # one colour a pixel pair
    packed = rgb_to_uyvy(rgb)
    decoded = uyvy_to_rgb(packed)
    assert np.abs(decoded - rgb).max() < 3 / 255  # chroma shared over pairs: within a rounding step
    assert np.array_equal(
        to_bgr8(packed.reshape(-1), "UYVY", 16, 4), np.clip(np.rint(decoded * 255), 0, 255)[..., ::-1].astype(np.uint8)
    )


def test_rig_files_accept_ten_bit_formats_and_refuse_an_odd_width() -> None:
    base = load_rig("sim-3x3").to_dict()
    for pf in ("Y210", "v210"):
        rig = rig_from_dict({**base, "format": {**base["format"], "pixel_format": pf}})
        assert rig.model.format.pixel_format == pf
    with pytest.raises(RigFileError, match="width_px must be even"):
        rig_from_dict({**base, "format": {**base["format"], "pixel_format": "Y210", "width_px": 961}})
