"""The renderer's logic on synthetic grids: exact shifts of a textured plane, the depth test, the
disocclusion fill from the background side, and the compiled kernels against the numpy/OpenCV reference
(``tests/render_reference.py``) on a layered scene, with a missing camera and odd image sizes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from render_reference import ReferenceRenderer, Src

from rigctl.render.warp import NONE, RING, Renderer, prepare


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


def test_a_disocclusion_takes_the_background_and_the_keyed_screen_stays_empty() -> None:
    h, w = 40, 80
    disp = np.full((h, w), np.inf, np.float32)  # the keyed screen: no disparity
    disp[:, 10:70] = 2.0  # a far plane
    disp[10:30, 30:50] = 12.0  # a near square in front of it
    rgb = np.full((h, w, 3), 0.2, np.float32)
    rgb[10:30, 30:50] = 0.9
    alpha = np.isfinite(disp).astype(np.float32)
    ren = Renderer([prepare("r0c0", (0.0, 0.0), rgb, alpha, disp)], taps=1)
    low = ren.splat(-1.0, 0.0, ren.sources)  # half resolution; the square moves 12 px, the plane 2 px
    # the plane behind the square's old place (full-resolution columns 32..41) was never seen: it is filled
    # with the farther of the two surfaces on either side, the plane, not the square
    assert np.all(low[6:14, 16:21] == 2.0), low[10, 12:26]
    assert np.all(low[6:14, 21:31] == 12.0)
    # the screen left of the plane stays empty beyond the key's soft edge (RING half-resolution pixels)
    assert np.all(low[:, : 6 - RING] == NONE)
    out = ren.render(-1.0, 0.0)
    assert np.all(out.rgba8[:, :8, 3] == 0) and np.all(out.rgba8[:, 14:70, 3] == 255)
    assert np.isinf(out.disparity[:, :8]).all()
    assert out.disparity[20, 36] == 2.0 and out.disparity[20, 50] == 12.0  # full resolution, as at half
    assert out.rgba[20, 20, 0] == pytest.approx(0.2, abs=0.01) and out.rgba[20, 50, 0] == pytest.approx(0.9, abs=0.01)


def test_taps_are_a_fixed_small_number() -> None:
    src = prepare("r0c0", (0.0, 0.0), np.zeros((8, 8, 3), np.float32), np.ones((8, 8), np.float32),
                  np.ones((8, 8), np.float32))  # fmt: skip
    with pytest.raises(ValueError, match="taps"):
        Renderer([src], taps=5)


def layered_scene(h: int, w: int) -> dict[str, tuple[tuple[float, float], np.ndarray, np.ndarray, np.ndarray]]:
    """A 3x3 grid seeing a textured far plane (with screen around it) and a textured near card, each camera
    rendered exactly: a point seen at x by the camera at offset 0 appears at x - d * offset."""
    rng = np.random.default_rng(3)
    far_tex = cv2.GaussianBlur(rng.random((h, w, 3)).astype(np.float32), (0, 0), 1.5)
    near_tex = cv2.GaussianBlur(rng.random((h, w, 3)).astype(np.float32), (0, 0), 1.5)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    views = {}
    for r in range(3):
        for c in range(3):
            ox, oy = c - 1.0, (r - 1.0) * 0.8
            rgb = np.zeros((h, w, 3), np.float32)
            disp = np.full((h, w), np.inf, np.float32)
            layers = ((3.0, far_tex, (4, h - 4, 8, w - 8)), (9.0, near_tex, (h // 3, 2 * h // 3, w // 3, w // 2)))
            for d, tex, (y0, y1, x0, x1) in layers:
                sx, sy = xs + d * ox, ys + d * oy  # where the reference camera saw this pixel's point
                inside = (sy >= y0) & (sy < y1) & (sx >= x0) & (sx < x1)
                sample = cv2.remap(tex, sx, sy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
                rgb[inside] = sample[inside]
                disp[inside] = d
            views[f"r{r}c{c}"] = ((ox, oy), rgb, np.isfinite(disp).astype(np.float32), disp)
    return views


@pytest.mark.parametrize("size", [(96, 128), (77, 101)])  # even, and odd both ways (the kernel's edge path)
def test_the_kernels_agree_with_the_reference(size: tuple[int, int]) -> None:
    views = layered_scene(*size)
    views["r0c2"][3][:] = np.inf  # a camera without a single disparity
    del views["r2c0"]  # and a camera that is missing
    fast = Renderer([prepare(n, o, rgb, a, d) for n, (o, rgb, a, d) in views.items()])
    ref = ReferenceRenderer([Src(n, o, rgb, a, d) for n, (o, rgb, a, d) in views.items()])
    for u, v, exclude in [(0.0, 0.0, ("r1c1",)), (0.37, -0.2, ()), (-0.9, 0.75, ()), (1.0, -0.8, ("r0c2",))]:
        got = fast.render(u, v, exclude)
        want_rgba, want_d = ref.render(u, v, exclude)
        assert got.sources == [s.name for s in ref.nearest(u, v, exclude)]
        assert "r2c0" not in got.sources and not set(exclude) & set(got.sources)
        # the target disparity (splat, depth test, closing, fill, ring) is the same to the bit
        assert np.array_equal(got.disparity, np.where(want_d > NONE, want_d, np.inf)), (u, v)
        # colour and alpha: the reference blends in 8 bits step by step with 1/32-pixel remap positions,
        # the kernel sums once with 1/128-pixel positions: a fraction of a level apart, except at a few
        # depth edges where a nearest disparity sample falls on the other side
        diff = np.abs(got.rgba8.astype(int) - np.round(want_rgba * 255).astype(int))
        assert diff.mean() < 0.5 and np.mean(diff > 3) < 0.005, (u, v, diff.mean(), np.mean(diff > 3))
        assert np.array_equal(got.rgba8[..., 3] == 0, want_rgba[..., 3] == 0)  # the same pixels transparent


def test_an_eye_pair_is_the_two_views_rendered_alone() -> None:
    views = layered_scene(64, 96)
    ren = Renderer([prepare(n, o, rgb, a, d) for n, (o, rgb, a, d) in views.items()])
    left, right = ren.render_pair((-0.25, 0.1), (0.25, 0.1))
    for got, u in ((left, -0.25), (right, 0.25)):
        alone = ren.render(u, 0.1)
        assert np.array_equal(got.rgba8, alone.rgba8) and np.array_equal(got.low, alone.low)
        assert got.sources == alone.sources
    assert not np.array_equal(left.rgba8, right.rgba8)  # two positions, two views


@pytest.mark.parametrize("threads", [1, 3])
def test_a_view_shaded_in_interleaved_rows_is_the_view_shaded_whole(threads: int) -> None:
    """One view's block rows go to every core, and each eye of a pair to its own: the image must not
    depend on how the rows were shared out (nor on which eye's scratch images a view used)."""
    views = layered_scene(77, 101)
    srcs = [prepare(n, o, rgb, a, d) for n, (o, rgb, a, d) in views.items()]
    whole = Renderer(srcs)
    whole.threads = 1
    shared = Renderer(srcs)
    shared.threads = threads
    for u, v in [(0.37, -0.2), (-0.9, 0.75)]:
        want = whole.render(u, v)
        got = shared.render(u, v)
        assert np.array_equal(got.rgba8, want.rgba8) and np.array_equal(got.low, want.low)
        left, right = shared.render_pair((u, v), (u + 0.1, v))
        assert np.array_equal(left.rgba8, want.rgba8)
        assert np.array_equal(right.rgba8, whole.render(u + 0.1, v).rgba8)


def test_a_stereo_eye_pair_is_rendered_as_a_pair() -> None:
    """``rigctl render --stereo``: the _L and _R eyes of a position go through ``render_pair`` (each eye on
    its own thread), a single position through ``render``; both give the views rendered alone."""
    from rigctl.render.bench import frame_from_arrays
    from rigctl.render.views import _rendered, eyes_for

    views = layered_scene(64, 96)
    frame = frame_from_arrays(views, focal=100.0, spacing=0.12)
    ren = Renderer([prepare(n, o, rgb, a, d) for n, (o, rgb, a, d) in views.items()])
    pairs: list[tuple[tuple[float, float], tuple[float, float]]] = []
    render_pair = ren.render_pair

    def counted(left: tuple[float, float], right: tuple[float, float], exclude: tuple[str, ...] = ()) -> object:
        pairs.append((left, right))
        return render_pair(left, right, exclude)

    ren.render_pair = counted  # type: ignore[method-assign]
    eyes = eyes_for(frame, 1.0, 1.0, 0.06) + eyes_for(frame, 0.5, 1.0, None)
    got = list(_rendered(ren, frame, eyes))
    assert [e.stem for e, _, _ in got] == ["c1r1_L", "c1r1_R", "c0.5r1"] and len(pairs) == 1
    for eye, res, ms in got:
        assert np.array_equal(res.rgba8, ren.render(*frame.position(eye.col, eye.row)).rgba8) and ms > 0


def test_a_source_prepared_over_the_last_frames_is_the_source_prepared_afresh() -> None:
    """A preview's next frame writes over the last frame's images (no fresh memory): the same source, and
    the views rendered from it those of a fresh renderer; another size gets images of its own."""
    from rigctl.render.bench import frame_from_arrays
    from rigctl.render.views import renderer_for

    first = frame_from_arrays(layered_scene(64, 96), focal=100.0, spacing=0.12)
    later = {n: (o, rgb[:, ::-1].copy(), a[:, ::-1].copy(), d[:, ::-1].copy()) for n, (o, rgb, a, d) in
             layered_scene(64, 96).items()}  # fmt: skip
    second = frame_from_arrays(later, focal=100.0, spacing=0.12)
    ren1 = renderer_for(first)
    was = {s.name: s.texture for s in ren1.sources}
    before = ren1.render(0.3, 0.2).rgba8.copy()
    ren2 = renderer_for(second, previous=ren1)
    fresh = renderer_for(second)
    for s, f in zip(ren2.sources, fresh.sources, strict=True):
        assert s.texture is was[s.name]  # written over, not made afresh
        for a, b in ((s.texture, f.texture), (s.disparity, f.disparity), (s.half, f.half), (s.spans, f.spans)):
            assert np.array_equal(a, b)
    assert np.array_equal(ren2.render(0.3, 0.2).rgba8, fresh.render(0.3, 0.2).rgba8)
    assert not np.array_equal(before, fresh.render(0.3, 0.2).rgba8)  # the frames differ
    small = frame_from_arrays(layered_scene(32, 48), focal=100.0, spacing=0.12)
    assert all(s.texture.shape == (32, 48) for s in renderer_for(small, previous=ren2).sources)
