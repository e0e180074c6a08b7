"""The matte held packed while a frame set's results wait for the write (rigctl.depth.packed): every bit of
the plane comes back, and a result holds about a byte a pixel of it, not four."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from rigctl.depth.estimate import DepthResult
from rigctl.depth.packed import BitPlane, FillPlane, PackedField, PackedPlane
from rigctl.keying import Keyer


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, np.float32).view(np.uint32)


def test_every_bit_of_the_plane_comes_back() -> None:
    rng = np.random.default_rng(5)
    plane = rng.random((37, 53), dtype=np.float32)
    plane[rng.random(plane.shape) < 0.4] = 0.0
    plane[rng.random(plane.shape) < 0.3] = 1.0
    specials = [-0.0, np.nan, np.inf, -np.inf, 1.0 + 2**-23, 2**-149, -1.0, 3.5]
    plane.reshape(-1)[: len(specials)] = specials
    packed = PackedPlane.of(plane)
    assert np.array_equal(_bits(packed.plane()), _bits(plane))  # -0.0 and NaN's payload included
    assert packed.plane().dtype == np.float32 and packed.shape == plane.shape
    for below in (plane, np.ones((4, 4), np.float32), np.full((4, 4), np.nan, np.float32), plane.clip(1, None)):
        assert PackedPlane.of(below).any_below_one() == bool((below < 1).any())


def test_a_keyers_matte_is_held_in_about_a_quarter_of_its_bytes() -> None:
    rgb = np.zeros((120, 160, 3), np.float32)
    rgb[..., 1] = 0.8  # a green screen
    rgb[30:100, 50:110] = (0.6, 0.5, 0.4)  # a subject
    rgb[30:100, 48:50] = (0.5, 0.7, 0.4)  # its edge, part screen
    matte = Keyer().matte(rgb)
    assert 0 < float(matte.mean()) < 1
    packed = PackedPlane.of(matte)
    assert packed.nbytes < 0.3 * matte.nbytes
    assert np.array_equal(_bits(packed.plane()), _bits(matte))


def test_a_result_holds_its_matte_packed_and_gives_it_back_whole() -> None:
    h, w = 24, 32
    matte = np.zeros((h, w), np.float32)
    matte[5:20, 8:25] = 1.0
    matte[5:20, 7] = 0.25
    no = np.zeros((h, w), bool)
    res = DepthResult(np.ones((h, w), np.float32), np.ones((h, w), np.float32), no, no.copy(), matte)
    assert "matte" not in res.__dict__ and PackedField.held(res, "matte").nbytes < matte.nbytes / 2
    assert np.array_equal(res.matte, matte) and res.keyed_a_screen()
    # what the farm and the tests do with results: pickle them, replace a field
    for other in (pickle.loads(pickle.dumps(res)), dataclasses.replace(res, keyed_by=None)):
        assert np.array_equal(_bits(other.matte), _bits(matte))
    res.matte = np.ones((h, w), np.float32)  # an assignment packs the new plane
    assert not res.keyed_a_screen() and float(res.matte.min()) == 1.0


def test_a_plane_packed_around_its_fill_comes_back_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    for fill in (np.inf, 0.0):
        plane = np.full((41, 67), fill, np.float32)
        plane[10:30, 20:50] = rng.random((20, 30), dtype=np.float32) * 300
        specials = [-0.0, 0.0, np.nan, np.inf, -np.inf, 2**-149, -1.0]
        plane.reshape(-1)[: len(specials)] = specials
        packed = FillPlane.of(plane, fill)
        assert np.array_equal(_bits(packed.plane()), _bits(plane))  # -0.0 beside 0.0, NaN's payload
        assert packed.nbytes < 0.3 * plane.nbytes  # the fill's pixels cost a bit each
    for empty in (np.zeros((0, 0), np.float32), np.full((3, 5), np.inf, np.float32)):
        assert np.array_equal(FillPlane.of(empty, np.inf).plane(), empty)


def test_a_mask_is_held_in_a_bit_a_pixel() -> None:
    rng = np.random.default_rng(3)
    for shape in ((37, 53), (1, 1), (0, 0), (8, 8)):
        mask = rng.random(shape) < 0.3
        packed = BitPlane.of(mask)
        assert np.array_equal(packed.plane(), mask) and packed.plane().dtype == bool
        assert packed.nbytes == (mask.size + 7) // 8


def test_a_results_planes_are_held_packed_and_read_only() -> None:
    """Every plane of a result: a read is a new read-only plane (an in-place write fails, it is not lost), an
    assignment packs the new plane, a result of the presenter's shape holds a few bytes a pixel."""
    h, w = 60, 80
    disparity = np.full((h, w), np.inf, np.float32)
    disparity[10:50, 30:50] = np.linspace(200, 260, 20, dtype=np.float32)
    confidence = np.where(np.isfinite(disparity), np.float32(0.7), np.float32(0.0))
    unreliable = np.zeros((h, w), bool)
    unreliable[20, 35] = True
    matte = np.isfinite(disparity).astype(np.float32)
    res = DepthResult(disparity, confidence, unreliable, unreliable.copy(), matte)
    held = sum(PackedField.held(res, f).nbytes for f in ("disparity", "confidence", "unreliable", "bound_hit", "matte"))
    assert held < 4 * h * w  # 15 bytes a pixel as planes
    assert np.array_equal(res.disparity, disparity) and np.array_equal(res.unreliable, unreliable)
    assert res.filled.shape == (0, 0)  # the default: none
    for name in ("disparity", "confidence", "unreliable", "bound_hit", "matte", "filled"):
        plane = getattr(res, name)
        with pytest.raises(ValueError, match="read-only"):
            plane[...] = plane.dtype.type(0)
    res.confidence = np.where(unreliable, np.float32(0.0), res.confidence)
    assert float(res.confidence[20, 35]) == 0.0 and float(res.confidence[21, 35]) == np.float32(0.7)
    again = pickle.loads(pickle.dumps(res))
    assert np.array_equal(again.confidence, res.confidence) and np.array_equal(again.unreliable, unreliable)
