"""The key is for a green screen: a scene without one (foliage, green props) is not keyed away."""

from __future__ import annotations

import numpy as np
import skimage.data

from rigctl.keying import Keyer


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
