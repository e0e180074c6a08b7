"""The soft key's wide blurs start from the weighted values shrunk by an area average (``LocalMean.shrunk``).
Issue 24: where the scale divides the frame it is made in bands of whole blocks, never the frame's weighted
values at once; the values are OpenCV's over the frame, bit for bit."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from rigctl import local_mean
from rigctl.local_mean import LocalMean, with_ones


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize("rows", [1, 40, 128, 10_000])
@pytest.mark.parametrize("shape", [(288, 384), (291, 385)])  # divided by 3, 4 and 16; and by none of them
def test_the_shrunk_weighted_values_in_bands_are_the_frames(
    monkeypatch: pytest.MonkeyPatch, rows: int, shape: tuple[int, int], compiled: bool
) -> None:
    """Numpy and OpenCV in bands, or the compiled shrink in one pass (``local_mean_kernels``): OpenCV's area
    resize of the frame's weighted values either way, bit for bit."""
    rng = np.random.default_rng(rows)
    values = with_ones(rng.random((*shape, 3), dtype=np.float32) * np.float32(1.5) - np.float32(0.2))
    weight = (rng.random(shape) > 0.6).astype(np.float32)
    mean = LocalMean(values, weight, (4.0, 16.0, 64.0))
    made = []
    real = mean.weighted
    monkeypatch.setattr(mean, "weighted", lambda box=None: made.append(box) or real(box))
    monkeypatch.setattr(local_mean, "SHRINK_ROWS", rows)
    monkeypatch.setattr(local_mean, "COMPILED", compiled)
    h, w = shape
    for scale in (3, 4, 16):
        made.clear()
        whole = cv2.resize(real(), (w // scale, h // scale), interpolation=cv2.INTER_AREA)
        got = mean.shrunk(scale)
        assert got.dtype == np.float32 and got.shape == whole.shape
        assert np.array_equal(got.view(np.uint32), whole.view(np.uint32))
        if h % scale or w % scale:
            assert made == [None]  # over the frame at once, as before
        elif compiled:
            assert made == []  # read in one pass, no weighted values made
        else:
            assert None not in made and all((b[1] - b[0]) % scale == 0 for b in made)
            assert len(made) == -(-h // (-(-rows // scale) * scale))  # bands of whole blocks


def test_a_fine_field_holds_only_the_tiles_made_and_reads_the_frames_blur() -> None:
    """Issue 24, the write's peak: a fine blur is held as the tiles made (N x TILE x TILE x C), not a frame
    whose pages a tile's rows touch (0.12 GiB a field at 4K); what it reads is OpenCV's blur over the frame,
    bit for bit, through calls that add tiles (the band, then the strands it grows), at the frame's edges."""
    rng = np.random.default_rng(7)
    h, w = 250, 333  # not whole tiles either way
    values = with_ones(rng.normal(0, 1, (h, w, 3)).astype(np.float32))
    weight = (rng.random((h, w)) > 0.3).astype(np.float32)
    mean = LocalMean(values, weight, (3.0, 12.0))
    whole = cv2.GaussianBlur(values * weight[..., None], (0, 0), 3.0).reshape(-1, 4)
    t = local_mean.TILE
    made = 0
    calls = ([0, w - 1], [(h - 1) * w + w - 1, 5 * w + 100, 5 * w + 101], [40 * w + 40])
    for idx in map(np.array, calls):
        got = mean.sample(0, idx)
        assert np.array_equal(got.view(np.uint32), whole[idx].view(np.uint32))
        ys, xs = np.divmod(idx, w)
        asked = {(int(y) // t, int(x) // t) for y, x in zip(ys, xs, strict=True)}
        assert asked <= {(int(a), int(b)) for a, b in np.argwhere(~mean.todo[0])}
        made = int((~mean.todo[0]).sum())
        assert mean.fields[0].shape == (made, t, t, 4)  # the tiles made, nothing of the frame's
    assert made == 5
    earlier = np.array([0, w - 1, 5 * w + 100])  # tiles made by earlier calls read the same after more were added
    assert np.array_equal(mean.sample(0, earlier).view(np.uint32), whole[earlier].view(np.uint32))


def test_weights_in_bytes_weigh_as_float_weights_bit_for_bit() -> None:
    """The soft key's weights are 0 and 1 in bytes (a quarter of float32's memory at the write's peak): every
    blur, fine on tiles, fine over the frame and wide at a coarser scale, reads the same bits."""
    rng = np.random.default_rng(8)
    h, w = 256, 320
    values = with_ones(rng.random((h, w, 3), dtype=np.float32))
    byte = (rng.random((h, w)) > 0.5).astype(np.uint8)
    as_bytes = LocalMean(values, byte, (4.0, 16.0, 64.0))
    as_float = LocalMean(values, byte.astype(np.float32), (4.0, 16.0, 64.0))
    assert np.array_equal(as_bytes.weighted().view(np.uint32), as_float.weighted().view(np.uint32))
    for scale in (3, 4, 16):  # the compiled shrink, through both weights' signatures
        assert np.array_equal(as_bytes.shrunk(scale).view(np.uint32), as_float.shrunk(scale).view(np.uint32))
    for idx in (rng.choice(h * w, 40, replace=False), np.arange(h * w)):
        for k in range(3):
            a, b = as_bytes.sample(k, idx), as_float.sample(k, idx)
            assert a.dtype == np.float32 and np.array_equal(a.view(np.uint32), b.view(np.uint32))


def test_the_coarse_scale_divides_the_frame_where_it_can() -> None:
    """About sigma / 4, the largest that divides both sides above half that: each coarse value a block's mean."""
    assert local_mean.coarse_scale(64.0, 2160, 3840) == 16
    assert local_mean.coarse_scale(64.0, 1080, 1920) == 15  # 16 does not divide 1080
    assert local_mean.coarse_scale(16.0, 1080, 1920) == 4
    assert local_mean.coarse_scale(12.0, 1080, 1920) == 3
    assert local_mean.coarse_scale(64.0, 1081, 1921) == 16  # nothing near divides: as before, the frame resized
    assert local_mean.coarse_scale(4.0, 1081, 1921) == 1 and local_mean.coarse_scale(2.0, 10, 10) == 1


@pytest.mark.parametrize("shape", [(1088, 384), (1080, 480)])  # scales 4 and 16; 4 and 15
def test_a_wide_field_is_shrunk_only_on_the_rows_read_and_reads_the_frames(
    monkeypatch: pytest.MonkeyPatch, shape: tuple[int, int]
) -> None:
    """Issue 24, the soft key's time: a wide blur (compiled, at a scale that divides the frame) shrinks only
    the coarse rows its blur reaches from the pixels read, more as later pixels need them; every value read
    is the one the frame's whole shrink and blur give, bit for bit, before and after rows are added."""
    rng = np.random.default_rng(11)
    h, w = shape
    values = with_ones(rng.random((h, w, 3), dtype=np.float32))
    weight = (rng.random((h, w)) > 0.5).astype(np.uint8)
    sigmas = (4.0, 16.0, 64.0)
    rows = LocalMean(values, weight, sigmas)
    for k in (1, 2):
        scale = rows.scale(k)
        whole = cv2.GaussianBlur(rows.shrunk(scale), (0, 0), sigmas[k] / scale)  # the frame's, all at once
        frame = LocalMean(values, weight, sigmas)
        frame.fields[k] = whole  # read through the same bilinear sampling, as the numpy path reads it

        def want(idx: np.ndarray, k: int = k, frame: LocalMean = frame) -> np.ndarray:
            with monkeypatch.context() as m:
                m.setattr(local_mean, "COMPILED", False)
                return frame.sample(k, idx).view(np.uint32)

        top = np.arange(5 * w, 6 * w)  # a row near the top
        got = rows.sample(k, top)
        assert np.array_equal(got.view(np.uint32), want(top))
        made = rows.have[k].copy()
        assert made[: 5 // scale + 1].all() and not made.all()  # the rows reached, not the frame
        bottom = np.arange((h - 3) * w, (h - 2) * w)
        got_bottom = rows.sample(k, bottom)
        assert np.array_equal(got_bottom.view(np.uint32), want(bottom))
        assert rows.have[k].sum() > made.sum()
        assert np.array_equal(rows.sample(k, top).view(np.uint32), got.view(np.uint32))  # unchanged
        left = LocalMean(values, weight, sigmas)  # a few pixels near the left edge: only the columns reached
        near = np.arange(100, 110) * w + 3
        assert np.array_equal(left.sample(k, near).view(np.uint32), want(near))
        assert left.have[k][:, 0].any() and not left.have[k][:, -1].any()
        everything = np.arange(h * w)
        assert np.array_equal(rows.sample(k, everything).view(np.uint32), want(everything))
        assert rows.have[k].all()
