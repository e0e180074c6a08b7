"""The matte held packed while a frame set's results wait for the write (rigctl.depth.packed): every bit of
the plane comes back, and a result holds about a byte a pixel of it, not four."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np

from rigctl.depth.estimate import DepthResult
from rigctl.depth.packed import PackedField, PackedPlane
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
