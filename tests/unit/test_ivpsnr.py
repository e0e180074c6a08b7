"""IV-PSNR on constructed cases whose values are worked out by hand (rigctl.interop.ivpsnr).

64x48 pictures, 8 bits, so N = 3072 pixels and the peak is 255. A component whose best matches are all
exact has SSD 0, counted as 1: 10 log10(3072 * 255^2) = 83.0050 dB (the cap). IV-PSNR averages Y:Cb:Cr
4:1:1."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rigctl.interop.ivpsnr import global_offset, ivpsnr, upsample_420

H, W = 48, 64
CAP = 10 * math.log10(3072 * 255**2)  # 83.0050


def textured(seed: int = 1) -> np.ndarray:
    """Random texture inside a flat 4-pixel frame (so a shifted copy still finds every pixel in the window)."""
    rng = np.random.default_rng(seed)
    pic = np.full((3, H, W), 120, np.uint16)
    pic[:, 4:-4, 4:-4] = rng.integers(16, 236, (3, H - 8, W - 8))
    return pic


def flat(y: int = 100) -> np.ndarray:
    pic = np.full((3, H, W), 128, np.uint16)
    pic[0] = y
    return pic


def test_the_cap_is_what_the_docstring_says() -> None:
    assert pytest.approx(83.0050, abs=1e-4) == CAP


def test_identical_pictures_score_the_cap() -> None:
    pic = textured()
    assert ivpsnr(pic, pic, 8).ivpsnr_db == pytest.approx(CAP, abs=1e-9)


def test_a_one_pixel_shift_is_forgiven_and_a_three_pixel_one_is_not() -> None:
    ref = textured()
    one = ref.copy()
    one[:, :, 1:] = ref[:, :, :-1]  # everything one pixel to the right: every match is exact
    r = ivpsnr(ref, one, 8)
    assert r.ivpsnr_db == pytest.approx(CAP, abs=1e-9)
    assert r.psnr_db[0] < 20  # plain PSNR punishes the shift
    three = ref.copy()
    three[:, :, 3:] = ref[:, :, :-3]  # beyond the search range of 2
    assert ivpsnr(ref, three, 8).ivpsnr_db < 30


def test_a_colour_offset_within_the_unnoticeable_difference_is_forgiven() -> None:
    ref = textured()
    test = (ref.astype(int) + np.array([2, 1, -1])[:, None, None]).astype(np.uint16)
    r = ivpsnr(ref, test, 8)
    assert r.offset == (2, 1, -1)
    assert r.ivpsnr_db == pytest.approx(CAP, abs=1e-9)


def test_a_colour_offset_beyond_it_is_forgiven_only_up_to_it() -> None:
    # flat Y 100 -> 105: the offset is clipped to round(0.01 * 255) = 3, leaving 2 at every pixel in Y:
    # PSNR_Y = 10 log10(255^2 / 2^2) = 42.1102 dB; Cb and Cr are exact (the cap).
    r = ivpsnr(flat(100), flat(105), 8)
    assert r.offset == (3, 0, 0)
    psnr_y = 10 * math.log10(255**2 / 4)
    assert psnr_y == pytest.approx(42.1102, abs=1e-4)
    assert r.ivpsnr_db == pytest.approx((4 * psnr_y + 2 * CAP) / 6, abs=1e-9)  # 55.7418
    assert r.ivpsnr_db == pytest.approx(55.7418, abs=1e-4)
    assert r.psnr_db[0] == pytest.approx(10 * math.log10(255**2 / 25), abs=1e-9)  # plain: all of the 5


def test_noise_is_not_forgiven() -> None:
    # flat Y plus +-1 noise: no offset (the mean rounds to 0), and every match is 1 off in Y whichever
    # neighbour it is: PSNR_Y = 10 log10(255^2) = 48.1308 dB.
    rng = np.random.default_rng(3)
    ref = flat(100)
    test = ref.copy()
    test[0] = 100 + rng.choice(np.array([-1, 1]), (H, W))
    r = ivpsnr(ref, test, 8)
    assert r.offset == (0, 0, 0)
    psnr_y = 10 * math.log10(255**2)
    assert r.ivpsnr_db == pytest.approx((4 * psnr_y + 2 * CAP) / 6, abs=1e-9)
    assert r.ivpsnr_db == pytest.approx(59.7555, abs=1e-4)


def test_a_mask_limits_the_comparison_to_its_pixels() -> None:
    ref = textured()
    test = ref.copy()
    test[:, 30:, :] = 16  # ruined below row 30
    mask = np.zeros((H, W), np.uint8)
    mask[6:20, 6:40] = 255
    assert ivpsnr(ref, test, 8, mask).ivpsnr_db == pytest.approx(10 * math.log10(14 * 34 * 255**3), abs=1e-9)
    assert ivpsnr(ref, test, 8).ivpsnr_db < 20


def test_the_global_offset_is_the_rounded_mean_half_to_even() -> None:
    ref = flat(100)
    test = flat(100)
    test[0, :, : W // 2] = 101  # mean +0.5 rounds to 0 (half to even), as the reference's SSE rounding
    assert tuple(global_offset(ref, test, 8)) == (0, 0, 0)


def test_upsampling_repeats_each_chroma_sample_over_its_block() -> None:
    y = np.zeros((4, 4), np.uint16)
    c = np.array([[1, 2], [3, 4]], np.uint16)
    up = upsample_420(y, c, c)
    assert up[1].tolist() == [[1, 1, 2, 2], [1, 1, 2, 2], [3, 3, 4, 4], [3, 3, 4, 4]]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"test": np.zeros((3, 4, 4), np.uint16)}, "differ in size"),
        ({"bit_depth": 16}, "bit depth"),
        ({"mask": np.zeros((H, W), np.uint8)}, "no non-zero"),
    ],
)
def test_bad_input_is_refused_in_one_sentence(kwargs: dict, message: str) -> None:
    args = {"ref": flat(), "test": flat(), "bit_depth": 8, **kwargs}
    with pytest.raises(ValueError, match=message):
        ivpsnr(**args)


@pytest.mark.parametrize("masked", [False, True])
def test_the_compiled_search_gives_the_numpy_search_to_the_bit(masked: bool) -> None:
    from rigctl.interop.ivpsnr import _one_way, one_way_numpy

    rng = np.random.default_rng(11)
    src = rng.integers(0, 8, (3, 40, 56)).astype(np.int32)  # few values: many ties between candidates
    other = rng.integers(0, 8, (3, 40, 56)).astype(np.int32)
    mask = (rng.random((40, 56)) > 0.4).astype(np.int32) * rng.integers(1, 256, (40, 56)).astype(np.int32)
    m = mask if masked else None
    assert _one_way(src, other, m, 2).tolist() == one_way_numpy(src, other, m, 2).tolist()
