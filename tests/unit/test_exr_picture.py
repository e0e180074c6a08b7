"""The EXR picture's compiled passes (``rigctl/exr_kernels.py``) against the numpy path they replaced
(``picture_reference``): the same alpha and premultiplied linear light bit for bit, on both sides of the
knee and at it, with sub-blacks, super-whites and mattes outside [0, 1]; NaN stays NaN; and what the compiled
passes do not take goes the numpy way."""

from __future__ import annotations

import numpy as np
import pytest

from rigctl import exr_kernels
from rigctl.exr import bt709_to_linear, picture, picture_reference


def _pictures(h: int = 67, w: int = 91) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(24)
    rgb = rng.uniform(-0.1, 1.2, (h, w, 3)).astype(np.float32)  # sub-blacks and super-whites as captured
    matte = rng.uniform(-0.3, 1.3, (h, w)).astype(np.float32)  # clipped to [0, 1]
    rgb[0, :3] = np.float32(4.5 * 0.018)  # the knee itself, and either side of it
    rgb[0, 3:6] = np.nextafter(np.float32(0.081), np.float32(0))
    rgb[0, 6:9] = np.nextafter(np.float32(0.081), np.float32(1))
    matte[1, :4] = (0.0, 1.0, -0.0, 0.5)
    return rgb, matte


def test_the_compiled_picture_is_numpys_bit_for_bit(monkeypatch: pytest.MonkeyPatch) -> None:
    rgb, matte = _pictures()
    ran = []
    real = exr_kernels.premultiply
    monkeypatch.setattr(exr_kernels, "premultiply", lambda *a: ran.append(1) or real(*a))
    got, want = picture(rgb, matte), picture_reference(rgb, matte)
    assert ran == [1]  # the compiled passes made it, not the reference
    assert set(got) == {"RGB", "A"} and got["RGB"].dtype == got["A"].dtype == np.float32
    assert got["RGB"].shape == rgb.shape and got["A"].shape == matte.shape
    assert np.array_equal(got["A"], want["A"]) and np.array_equal(got["RGB"], want["RGB"])
    assert (rgb < np.float32(0.081)).any() and (rgb > 1).any() and (matte < 0).any() and (matte > 1).any()
    assert np.array_equal(got["RGB"][matte <= 0], np.zeros_like(got["RGB"][matte <= 0]))
    whole = matte >= 1  # the linear light itself where the subject is whole
    assert whole.any() and np.array_equal(got["RGB"][whole], bt709_to_linear(rgb)[whole])


def test_nan_stays_nan_as_in_numpys_path() -> None:
    rgb, matte = _pictures(4, 5)
    rgb[2, 2, 1] = np.nan
    matte[3, 3] = np.nan
    got, want = picture(rgb, matte), picture_reference(rgb, matte)
    assert np.array_equal(np.isnan(got["RGB"]), np.isnan(want["RGB"]))
    assert np.array_equal(np.isnan(got["A"]), np.isnan(want["A"])) and np.isnan(got["A"][3, 3])
    assert np.isnan(got["RGB"][2, 2, 1]) and np.isnan(got["RGB"][3, 3]).all()


def test_what_the_compiled_pass_does_not_take_goes_the_numpy_way() -> None:
    rgb, matte = _pictures(8, 10)
    for args in (
        (rgb.astype(np.float64), matte),  # another type
        (rgb[:, ::2], matte[:, ::2]),  # a view, not in memory order
        (rgb, None),  # no matte: opaque
    ):
        got, want = picture(*args), picture_reference(*args)
        assert all(np.array_equal(got[k], want[k]) for k in want)
    assert np.array_equal(picture(rgb, None)["A"], np.ones(matte.shape, np.float32))
    empty = np.zeros((0, 0, 3), np.float32)
    assert picture(empty, np.zeros((0, 0), np.float32))["RGB"].shape == (0, 0, 3)


@pytest.mark.parametrize("rows", [1, 7, 64, 1000])
@pytest.mark.parametrize("colour", ["rec709", "acescg"])
def test_the_half_picture_in_bands_is_the_whole_picture_in_half_floats(
    monkeypatch: pytest.MonkeyPatch, rows: int, colour: str
) -> None:
    """Issue 24: the EXR's picture made band by band straight into half floats gives the bits of the whole
    picture rounded to half floats (what the write did before), with and without a matte, NaN included."""
    from rigctl import exr
    from rigctl.exr import half_picture

    monkeypatch.setattr(exr, "HALF_BAND_ROWS", rows)
    ran = []
    real = exr_kernels.premultiply_half
    monkeypatch.setattr(exr_kernels, "premultiply_half", lambda *a: ran.append(1) or real(*a))
    rgb, matte = _pictures()
    rgb[5, 5, 0], matte[6, 6] = np.nan, np.nan
    for m in (matte, None):
        got, want = half_picture(rgb, m, colour), picture(rgb, m, colour)
        assert set(got) == set(want) == {"RGB", "A"}
        for k in want:
            assert got[k].dtype == np.float16 and got[k].shape == want[k].shape
            assert np.array_equal(got[k].view(np.uint16), want[k].astype(np.float16).view(np.uint16))
        # rounded by the compiled pass where the picture is (a matte, Rec. 709), else numpy's cast
        assert bool(ran) == (m is not None and colour == "rec709")
        ran.clear()
    empty = half_picture(np.zeros((0, 4, 3), np.float32), np.zeros((0, 4), np.float32), colour)
    assert empty["RGB"].shape == (0, 4, 3) and empty["A"].shape == (0, 4)


def test_half_bits_round_as_numpys_cast() -> None:
    """The compiled rounding to half floats (``exr_kernels.half_bits``) against numpy's float32-to-float16
    cast: every float32 whose bits lie near a half's rounding boundaries (ties to even, both sides), in every
    exponent (overflow to infinity, the subnormals, underflow to a signed zero), NaNs with any significand,
    and random bits. (All 2^32 float32 patterns were compared once, 338 s: none differed.)"""
    from numba import njit

    half_bits = exr_kernels.half_bits

    @njit(cache=False)
    def cast(bits: np.ndarray) -> np.ndarray:  # pragma: no cover  (compiled)
        out = np.empty(bits.size, np.uint16)
        for i in range(bits.size):
            out[i] = half_bits(bits[i])
        return out

    top = np.arange(512, dtype=np.uint32) << np.uint32(23)  # sign and exponent, every one
    low = np.unique(
        np.concatenate(
            [
                np.arange(0, 1 << 14, dtype=np.uint32),  # the bits below a normal half's last place, all
                np.array([0x7FFFFF, 0x7FE000, 0x7FF000, 0x400000, 0x000001], np.uint32),
                np.random.default_rng(5).integers(0, 1 << 23, 2000, dtype=np.uint32),
            ]
        )
    )
    for lows in (low, (low << np.uint32(9)) & np.uint32(0x7FFFFF)):  # and the high significand bits
        bits = (top[:, None] | lows[None, :]).reshape(-1)
        with np.errstate(over="ignore"):
            want = bits.view(np.float32).astype(np.float16).view(np.uint16)
        assert np.array_equal(cast(bits), want)
