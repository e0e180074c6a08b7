"""The renderer's logic on synthetic grids: exact shifts of a textured plane, the background-side fill and
the depth test."""

from __future__ import annotations

import cv2
import numpy as np

from rigctl.render.warp import NONE, Renderer, _fill_background_side, prepare


def test_a_gap_between_two_surfaces_takes_the_farther_one_and_the_screen_stays_empty() -> None:
    t = np.full((1, 12), NONE, np.float32)
    t[0, 1:3] = 20.0  # near
    t[0, 6:9] = 5.0  # far
    out = _fill_background_side(t, max_gap=8)
    assert np.all(out[0, 3:6] == 5.0)  # the disocclusion between them: background side
    assert out[0, 0] == NONE and np.all(out[0, 9:] == NONE)  # outside: the keyed background, left empty
    assert np.all(_fill_background_side(t, max_gap=2)[0, 3:6] == NONE)  # wider than any parallax: not filled


def test_a_textured_plane_is_rendered_exactly_between_cameras() -> None:
    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur(rng.random((120, 400)).astype(np.float32), (0, 0), 2.0)
    d = 6.0
    sources = []
    for c in range(3):
        shift = np.float32([[1, 0, 100 + d * (c - 1)], [0, 1, 0]])
        img = cv2.warpAffine(base, shift, (160, 120), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
        rgb = np.repeat(img[..., None], 3, axis=2)
        sources.append(
            prepare(f"r0c{c}", (c - 1.0, 0.0), rgb, np.ones((120, 160), np.float32), np.full((120, 160), d, np.float32))
        )
    ren = Renderer(sources, taps=2)
    out = ren.render(0.5, 0.0)  # halfway between r0c1 and r0c2
    shift = np.float32([[1, 0, 100 + d * 0.5], [0, 1, 0]])
    want = cv2.warpAffine(base, shift, (160, 120), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP)
    inner = (slice(5, -5), slice(10, -10))
    assert np.abs(out.rgba[..., 0][inner] - want[inner]).mean() < 0.01
    assert np.allclose(out.disparity[inner], d) and np.all(out.rgba[..., 3][inner] > 0.99)
    assert sorted(out.sources) == ["r0c1", "r0c2"]


def test_the_nearer_surface_wins_the_depth_test() -> None:
    h, w = 40, 60
    disp = np.full((h, w), 2.0, np.float32)
    disp[10:30, 20:40] = 12.0  # a near square in front of a far plane
    rgb = np.zeros((h, w, 3), np.float32)
    rgb[10:30, 20:40] = 1.0
    src = prepare("r0c0", (0.0, 0.0), rgb, np.ones((h, w), np.float32), disp)
    out = Renderer([src], taps=1).render(-1.0, 0.0)  # one spacing to the left: near moves 12 px, far 2 px
    assert np.allclose(out.disparity[15:25, 34:50], 12.0)
    assert out.rgba[20, 40, 0] > 0.9  # the near square's colour, not the plane behind it
