"""The key is for a green screen: a scene without one (foliage, green props) is not keyed away."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import skimage.data

from rigctl import keying
from rigctl.keying import Keyer
from rigctl.local_mean import LocalMean as _LocalMean


def _screen_behind_a_subject(h: int = 300, w: int = 400) -> tuple[np.ndarray, np.ndarray]:
    yy, xx = np.mgrid[0:h, 0:w]
    light = 0.6 + 0.4 * np.exp(-((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / (2 * (0.4 * w) ** 2))  # uneven light
    rgb = np.dstack([0.1 * light, 0.55 * light, 0.15 * light]).astype(np.float32)
    subject = np.zeros((h, w), bool)
    subject[80:260, 150:260] = True
    tex = skimage.data.camera()[:h, :w].astype(np.float32) / 255
    rgb[subject] = np.dstack([tex, 0.8 * tex, 0.7 * tex])[subject]
    return rgb, subject


def test_an_unevenly_lit_screen_is_keyed_and_the_subject_kept() -> None:
    rgb, subject = _screen_behind_a_subject()
    rng = np.random.default_rng(0)
    rgb = np.clip(rgb + rng.normal(0, 0.01, rgb.shape), 0, 1).astype(np.float32)  # sensor noise
    a = Keyer().matte(rgb)
    assert np.mean(a[subject] > 0.5) > 0.97
    assert np.mean(a[~subject] < 0.5) > 0.97


def test_textured_foliage_is_not_a_screen() -> None:
    g = skimage.data.grass()[:300, :400].astype(np.float32) / 255
    foliage = np.dstack([0.3 * g, 0.65 * g, 0.2 * g]).astype(np.float32)
    assert Keyer().screen_excess(foliage) == 0.0
    assert np.all(Keyer().matte(foliage) == 1.0)
    scene = skimage.data.astronaut()[:300, :400].astype(np.float32) / 255
    scene[:, :150] = foliage[:, :150]  # a plant beside the subject, reaching the frame's edge
    assert np.all(Keyer().matte(scene) == 1.0)


def test_a_small_green_prop_is_not_a_screen() -> None:
    scene = skimage.data.astronaut()[:300, :400].astype(np.float32) / 255
    scene[100:110, 100:110] = (0.1, 0.6, 0.1)  # 0.08 % of the view, flat green
    assert np.all(Keyer().matte(scene) == 1.0)


def test_the_soft_key_of_an_empty_picture_is_empty() -> None:
    """A degenerate input: no pixels, no key, not an error (the soft key's range test reads the picture's
    minimum and maximum, which an empty array has not)."""
    key = Keyer().soft(np.zeros((0, 0, 3), np.float32))
    assert key.alpha.shape == (0, 0) and key.foreground.shape == (0, 0, 3) and key.solved == 0


def test_the_soft_keys_fine_blur_on_tiles_is_the_frames_bit_for_bit() -> None:
    """The fine local means are blurred only on the tiles the key reads (issue 24: the write): at every pixel
    asked for, the value OpenCV's blur of the whole frame has, bit for bit; at the frame's edges and corners,
    in frames whose sizes the tile does not divide, for scattered pixels, for runs of tiles reaching the right
    edge, asked for in several calls (the band, then the strands it grows) and once for most of the frame."""
    rng = np.random.default_rng(24)
    for h, w in ((200, 301), (97, 1920), (64, 64), (5, 7)):
        values = rng.normal(0, 1, (h, w, 4)).astype(np.float32)
        weight = (rng.random((h, w)) > 0.4).astype(np.float32)
        for sigma in (3.0, 4.0):
            mean = _LocalMean(values, weight, (sigma, 4 * sigma))
            whole = cv2.GaussianBlur(mean.weighted(), (0, 0), sigma).reshape(-1, 4)
            corners = np.array([0, w - 1, (h - 1) * w, h * w - 1])
            edge_rows = np.concatenate([np.arange(w), (h - 1) * w + np.arange(w)])
            scattered = rng.choice(h * w, size=max(1, h * w // 400), replace=False)
            for idx in (corners, scattered, edge_rows[::7], np.arange(h * w)):
                assert np.array_equal(mean.sample(0, idx), whole[idx])
            assert not mean.todo[0].any()  # the last asked for everything: made over the frame at once
    values = rng.normal(0, 1, (200, 301, 4)).astype(np.float32)
    part = _LocalMean(values, np.ones((200, 301), np.float32), (3.0,))
    part.sample(0, np.array([300]))  # one tile at the right edge: only it is made
    assert part.todo[0].sum() == part.todo[0].size - 1
    calls = []
    real = cv2.GaussianBlur
    try:  # scattered tiles whose margins add up to half the frame or more: the frame's blur, once
        cv2.GaussianBlur = lambda src, *a: calls.append(src.shape) or real(src, *a)
        ty, tx = np.mgrid[0:200:32, 0:301:32]
        checker = ((ty + tx) // 32) % 2 == 0
        part.sample(0, (ty[checker] * 301 + tx[checker]).ravel())
    finally:
        cv2.GaussianBlur = real
    assert calls == [(200, 301, 4)] and not part.todo[0].any()


def test_a_local_mean_holds_no_frame_of_weighted_values() -> None:
    """Issue 24, the write's peak: the weighted values (H x W x 4 float32, 133 MB at 4K) are made where a blur
    reads them, not held by each mean; any box of them is the frame's product there, bit for bit."""
    rng = np.random.default_rng(5)
    values = rng.normal(0, 1, (120, 170, 4)).astype(np.float32)
    weight = (rng.random((120, 170)) > 0.5).astype(np.float32)
    mean = _LocalMean(values, weight, (3.0, 12.0))
    mean.sample(0, np.array([5, 170 * 60 + 80]))  # a fine field's tiles made: its own field, not the product
    held = [v for v in vars(mean).values() if isinstance(v, np.ndarray)]
    assert all(v is values or v is weight for v in held)
    whole = values * weight[..., None]
    assert np.array_equal(mean.weighted(), whole)
    assert np.array_equal(mean.weighted((7, 90, 33, 170)), whole[7:90, 33:170])


def test_the_ycc_in_bands_of_rows_is_the_whole_pictures_bit_for_bit(monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 24, the write's peak: the key's Y, Cb, Cr are made a band of rows at a time, the same bits as the
    whole picture's product, whether the band divides the picture or not."""
    rng = np.random.default_rng(3)
    rgb = (rng.random((131, 77, 3), dtype=np.float32) * np.float32(1.2) - np.float32(0.1)).astype(np.float32)
    whole = np.asarray(rgb @ keying.RGB_TO_YCC.T, np.float32)
    for rows in (1, 7, 64, 500):
        monkeypatch.setattr(keying, "YCC_BAND_ROWS", rows)
        got = keying.ycc_with_ones(rgb)
        assert got.shape == (131, 77, 4) and got.dtype == np.float32
        assert np.array_equal(got[..., :3].view(np.uint32), whole.view(np.uint32))
        assert np.all(got[..., 3] == 1.0)


def test_a_key_that_makes_its_picture_itself_is_the_same_key_and_keeps_the_new_picture() -> None:
    """Issue 24, the write's peak: given no picture but a way to make it, the key makes it, lets go of it while
    it is solved (no caller holds it) and makes it again for its colour (no copy): the same alpha and colour,
    bit for bit, with a screen and without one, and with a picture beyond [0, 1] (clipped for the key, kept
    for the colour); with neither, one clear error."""
    rgb, _ = _screen_behind_a_subject()
    bright = rgb.copy()
    bright[100:120, 160:200] = 1.3  # super-whites on the subject
    no_screen = skimage.data.astronaut()[:120, :160].astype(np.float32) / 255
    for picture in (rgb, bright, no_screen):
        made: list[np.ndarray] = []

        def again(picture: np.ndarray = picture, made: list[np.ndarray] = made) -> np.ndarray:
            made.append(picture.copy())
            return made[-1]

        reference = Keyer().soft(picture)
        key = Keyer().soft(None, again=again)
        assert np.array_equal(key.alpha.view(np.uint32), reference.alpha.view(np.uint32))
        assert np.array_equal(key.foreground.view(np.uint32), reference.foreground.view(np.uint32))
        assert key.foreground is made[-1]  # the picture made last is the colour: not copied
        assert len(made) == (1 if picture is no_screen else 2)  # made again only when there is a key to solve
        assert key.solved == reference.solved
    with pytest.raises(ValueError, match="no picture"):
        Keyer().soft(None)


def test_a_hard_matte_given_is_made_again_where_it_cannot_be_the_clipped_pictures() -> None:
    """The depth's matte spares the key its own only where it is the clipped picture's: a picture beyond [0, 1]
    (clipped first) or of another shape has its matte made again, so the key is the key of the picture."""
    rgb, _ = _screen_behind_a_subject()
    bright = rgb.copy()
    bright[100:120, 160:200] = 1.3
    wrong = np.zeros(rgb.shape[:2], np.float32)  # a matte that would key everything away
    for picture in (bright, rgb[:, :-2].copy()):
        assert np.array_equal(Keyer().soft(picture, wrong).alpha, Keyer().soft(picture).alpha)
    assert not np.array_equal(Keyer().soft(rgb, wrong).alpha, Keyer().soft(rgb).alpha)  # used where it may be
