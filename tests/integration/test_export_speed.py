"""Issue 24's faster write path gives the outputs the reference path gives: the soft key started from the
hard matte depth computed (not keyed again) is bit-exact, the soft key's local means are within float32
rounding of the slower form they replaced, and the key solved on the edge band is the key solved everywhere
but for the screen's noise."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

import rigctl.depth.export as export
from rigctl.depth.estimate import DepthResult
from rigctl.depth.export import Target, write_outputs
from rigctl.depth.grid import Grid
from rigctl.depth.options import DepthOptions
from rigctl.depth.pipeline import TakeProcessor
from rigctl.depth.sources import OneGrid
from rigctl.exr import read_exr
from rigctl.keying import Keyer
from rigctl.local_mean import coarse_scale
from rigctl.local_mean import local_mean as _local_mean

CAMS = ("r0c0", "r0c1", "r0c2")
H, W = 96, 128


def _picture(shift: float, frame: int) -> np.ndarray:
    """A green screen (smooth, a little noise) with a textured subject whose edges are soft, ``shift`` px left."""
    rng = np.random.default_rng(frame)
    img = np.empty((H, W, 3), np.float32)
    img[...] = (0.12, 0.62, 0.16)
    img += rng.normal(0, 0.004, img.shape).astype(np.float32)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    x0 = 44 - shift + 2 * frame
    cover = np.clip(np.minimum(xx - x0, x0 + 40 - xx) / 2 + 0.5, 0, 1) * np.clip(np.minimum(yy - 20, 76 - yy), 0, 1)
    texture = 0.45 + 0.25 * np.sin(xx * 0.9 + shift * 0.9) * np.cos(yy * 0.7)
    subject = np.stack([texture, 0.6 * texture, 0.5 * texture + 0.1], axis=2).astype(np.float32)
    out = cover[..., None] * subject + (1 - cover[..., None]) * img
    return np.clip(out, 0, 1).astype(np.float32)


def _grid(frame: int = 0) -> Grid:
    d = 4.0
    images = {c: _picture(d * i, frame) for i, c in enumerate(CAMS)}
    offsets = {c: (float(i), 0.0) for i, c in enumerate(CAMS)}
    return Grid(list(CAMS), images, offsets, focal_px=100.0, spacing=0.1, meta={"frame": frame})


OPT = DepthOptions(preset="fast", disparity_range=(0.0, 10.0), warmup=0)


@pytest.fixture(scope="module")
def computed() -> tuple[Grid, dict[str, DepthResult]]:
    grid = _grid()
    results = TakeProcessor(OneGrid(grid), OPT).depth(grid)
    assert all(bool((r.matte < 1).any()) and bool((r.matte > 0).any()) for r in results.values())  # keyed
    return grid, results


def _reference_local_mean(values: np.ndarray, weight: np.ndarray, sigmas: tuple[float, ...]) -> tuple:
    """The soft key's local mean as it was before issue 24's write work (the products rebuilt per sigma and
    the division through gathered copies): the reference the in-place form must match bit for bit."""
    out = np.zeros(values.shape, np.float32)
    done = np.zeros(weight.shape, bool)
    h, w = weight.shape
    for sigma in sigmas:
        both = np.concatenate([values * weight[..., None], weight[..., None]], axis=2)
        scale = coarse_scale(sigma, h, w)
        if scale > 1:
            small = cv2.resize(both, (max(1, w // scale), max(1, h // scale)), interpolation=cv2.INTER_AREA)
            both = cv2.resize(cv2.GaussianBlur(small, (0, 0), sigma / scale), (w, h), interpolation=cv2.INTER_LINEAR)
        else:
            both = cv2.GaussianBlur(both, (0, 0), sigma)
        num, den = both[..., :-1], both[..., -1]
        take = ~done & (den > 0.02)
        out[take] = num[take] / den[take][:, None]
        done |= take
    return out, done.astype(np.float32)


def test_the_local_mean_matches_the_reference() -> None:
    """Bit for bit where the blur is over the frame; within float32 rounding (a few units in the last place,
    1e-6 here) where the wide blurs are read from the coarse scale at each pixel rather than enlarged to the
    frame: OpenCV enlarges in its own order of operations. Where there was weight at all, exactly."""
    rng = np.random.default_rng(3)
    for shape in ((90, 130), (91, 133)):  # and a size the coarse scales do not divide
        values = rng.random((*shape, 3), dtype=np.float32)
        weight = (rng.random(shape) > 0.97).astype(np.float32)  # sparse: the later sigmas fill the holes
        weight[:, :40] = 0.0  # a wide hole only the widest sigma reaches
        for sigmas in ((4.0, 16.0, 64.0), (3.0, 12.0)):
            got, got_done = _local_mean(values, weight, sigmas)
            want, want_done = _reference_local_mean(values, weight, sigmas)
            assert 0 < want_done.mean() < 1 or sigmas[-1] == 64.0
            assert np.array_equal(got_done, want_done)
            assert np.abs(got - want).max() <= 1e-6
            fine = _reference_local_mean(values, weight, sigmas[:1])[1] > 0  # the first sigma: over the frame
            assert np.array_equal(got[fine], want[fine])


def test_the_soft_key_from_depths_matte_is_the_soft_key_of_the_picture(
    computed: tuple[Grid, dict[str, DepthResult]], monkeypatch: pytest.MonkeyPatch
) -> None:
    grid, results = computed
    reference = {c: Keyer().soft(grid.images[c]) for c in CAMS}
    calls = []
    original = Keyer.matte
    monkeypatch.setattr(Keyer, "matte", lambda self, rgb: calls.append(1) or original(self, rgb))
    for cam in CAMS:
        assert results[cam].keyed_by == Keyer()
        key = export.soft_key(grid.images[cam], results[cam])
        assert np.array_equal(key.alpha, reference[cam].alpha)
        assert np.array_equal(key.foreground, reference[cam].foreground)
        assert 0 < float(key.alpha.mean()) < 1 and bool(((key.alpha > 0) & (key.alpha < 1)).any())  # soft edges
    assert calls == []  # depth's matte was used, the picture not keyed again
    # a picture beyond [0, 1] (super-whites) is keyed as the soft key does, clipped: depth's matte is not reused
    bright = np.asarray(grid.images[CAMS[0]]) * np.float32(1.6)
    assert float(bright.max()) > 1
    key = export.soft_key(bright, results[CAMS[0]])
    assert calls == [1]
    assert np.array_equal(key.alpha, Keyer().soft(bright).alpha)


def _decoded(path: Path) -> tuple[dict, dict]:
    channels, header = read_exr(path)
    return channels, header


def test_the_depth_exr_is_the_one_the_reference_path_writes(
    computed: tuple[Grid, dict[str, DepthResult]], tmp_path: Path
) -> None:
    """The same outputs with depth's matte reused and with the picture keyed again (a result that does not
    say which keyer made its matte): decoded channels, header attributes and the bytes themselves."""
    grid, results = computed
    for cam in CAMS:
        fast, slow = Target(tmp_path / "fast", "frames", 0, 25.0), Target(tmp_path / "slow", "frames", 0, 25.0)
        write_outputs(fast, cam, grid, results[cam], (0.0, 10.0), ("exr",))
        unknown = dataclasses.replace(results[cam], keyed_by=None)
        write_outputs(slow, cam, grid, unknown, (0.0, 10.0), ("exr",))
        a, b = fast.path(cam, ".exr"), slow.path(cam, ".exr")
        (ca, ha), (cb, hb) = _decoded(a), _decoded(b)
        assert ca.keys() == cb.keys() and all(np.array_equal(ca[k], cb[k], equal_nan=True) for k in ca)
        assert 0 < float(ca["A"].mean()) < 1
        assert {k: str(v) for k, v in ha.items()} == {k: str(v) for k, v in hb.items()}
        assert a.read_bytes() == b.read_bytes()


def test_a_frame_sets_report_times_its_write_elapsed_and_in_cpu_seconds(tmp_path: Path) -> None:
    from rigctl.depth.export import Exporter

    every = ("exr", "pfm", "png")
    done = TakeProcessor(OneGrid(_grid()), OPT, exporter=Exporter(tmp_path, formats=every, atomic=True)).process(0)
    t = done.report.timings_s
    assert t.depth > 0 and t.write > 0 and t.write_cpu > 0
    assert sorted(done.files) == sorted(f"{c}.{e}" for c in CAMS for e in every)
    # each file's record, made by the thread that fsyncs each staged file once it is written, is what was
    # published
    from rigctl.depth.export import file_record

    folder = tmp_path / "000000"
    assert {n: file_record(folder / n) for n in done.files} == done.files
    assert not list(tmp_path.glob(".partial-*"))


def test_screen_noise_away_from_the_subject_stays_screen() -> None:
    """The key solved everywhere finds specks of the subject in the screen's noise (alpha a little over the
    noise floor, false foreground); solved on the edge band the screen away from the subject is 0, and
    near it the key is the same within the shift those specks make in the screen's estimate."""
    keyer = Keyer()
    for frame in range(3):
        img = _picture(4.0 * frame, frame)
        band, everywhere = keyer.soft(img), keyer.soft(img, everywhere=True)
        hard = keyer.matte(img)
        distance = cv2.distanceTransform((hard <= 0).astype(np.uint8), cv2.DIST_L2, 5)
        far = distance > 8
        assert int((everywhere.alpha[far] > 0).sum()) > 50 and everywhere.alpha[far].max() < 0.1
        assert not band.alpha[far].any()
        diff = np.abs(band.alpha - everywhere.alpha)
        assert diff[distance <= 2].max() < 1e-3 and diff.max() < 0.1  # the edge, and specks beside it
        assert band.solved < 0.5 * everywhere.solved


def test_the_threaded_write_writes_what_one_thread_writes(
    computed: tuple[Grid, dict[str, DepthResult]], tmp_path: Path
) -> None:
    """The soft key made beside the PFM and PNG, and the EXR compressed on OpenEXR's thread pool, give the
    bytes the same steps give one after the other on one thread."""
    import OpenEXR

    grid, results = computed
    for cam in CAMS:
        threaded = Target(tmp_path / "threaded", "frames", 0, 25.0)
        write_outputs(threaded, cam, grid, results[cam], (0.0, 10.0), ("exr", "pfm", "png"))
        pool = OpenEXR.global_thread_count()
        assert pool >= 1  # the first EXR written set it
        OpenEXR.set_global_thread_count(0)  # the writer's own thread compresses
        try:
            one = Target(tmp_path / "one", "frames", 0, 25.0)
            key = export.soft_key(grid.images[cam], results[cam])
            pic = export.exr_picture(grid, cam, results[cam], key, one.colour)
            export.write_depth_exr(one, cam, grid, pic, export.depth_channels(grid, cam, results[cam]))
        finally:
            OpenEXR.set_global_thread_count(pool)
        assert threaded.path(cam, ".exr").read_bytes() == one.path(cam, ".exr").read_bytes()
        assert threaded.path(cam, ".pfm").is_file() and threaded.path(cam, ".png").is_file()


def test_a_soft_key_that_fails_fails_the_write(
    computed: tuple[Grid, dict[str, DepthResult]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An error in the key's thread is the write's error, and no EXR is left at its name."""
    grid, results = computed

    def broken(*_: object, **__: object) -> None:
        raise MemoryError("the soft key ran out of memory")

    monkeypatch.setattr(export, "soft_key", broken)
    target = Target(tmp_path, "frames", 0, 25.0)
    with pytest.raises(MemoryError, match="soft key"):
        write_outputs(target, CAMS[0], grid, results[CAMS[0]], (0.0, 10.0), ("exr", "pfm", "png"))
    assert not target.path(CAMS[0], ".exr").exists()


def test_the_next_cameras_key_is_made_while_this_one_writes_its_exr(
    computed: tuple[Grid, dict[str, DepthResult]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 24: a frame set's cameras are written one after another, the next camera's soft key made in the
    second thread while this camera's EXR is compressed and written (each EXR waits here until the next
    camera's key has started: written one step after another, it would wait in vain); and the files are
    the bytes each camera written alone gives."""
    import threading

    grid, results = computed
    started = {c: threading.Event() for c in CAMS}
    real_key, real_exr = export.soft_key, export.write_depth_exr

    def key(image: np.ndarray, res: DepthResult, again: Callable[[], np.ndarray] | None = None) -> object:
        started[next(c for c in CAMS if results[c] is res)].set()
        return real_key(image, res, again)

    overlapped = []

    def exr(target: Target, name: str, *args: object) -> None:
        after = CAMS[CAMS.index(name) + 1 :]
        overlapped.append(not after or started[after[0]].wait(timeout=20.0))
        real_exr(target, name, *args)

    monkeypatch.setattr(export, "soft_key", key)
    monkeypatch.setattr(export, "write_depth_exr", exr)
    together = Target(tmp_path / "together", "frames", 0, 25.0)
    export.write_all(together, grid, dict(results), (0.0, 10.0), ("exr", "pfm", "png"))
    assert overlapped == [True] * len(CAMS)
    monkeypatch.setattr(export, "soft_key", real_key)
    monkeypatch.setattr(export, "write_depth_exr", real_exr)
    for cam in CAMS:
        alone = Target(tmp_path / cam, "frames", 0, 25.0)
        write_outputs(alone, cam, grid, results[cam], (0.0, 10.0), ("exr", "pfm", "png"))
        for ext in (".exr", ".pfm", ".png"):
            assert together.path(cam, ext).read_bytes() == alone.path(cam, ext).read_bytes()


@pytest.mark.parametrize("d_range", [(74.06, 112.29), (100.0, 100.0), (120.0, 80.0), (-5.5, 300.25), (0.0, 1e-30)])
def test_the_compiled_preview_is_the_reference_bit_for_bit(d_range: tuple[float, float]) -> None:
    rng = np.random.default_rng(7)
    d = (rng.random((67, 131)) * 320 - 10).astype(np.float32)
    u = rng.random(d.shape)
    d[u < 0.1] = np.inf
    d[(u >= 0.1) & (u < 0.12)] = np.nan
    d[(u >= 0.12) & (u < 0.13)] = -np.inf
    got = export.colour_preview(d, d_range)
    ref = export.colour_preview_reference(d, d_range)
    assert got.dtype == np.uint8 and got.shape == (67, 131, 3)
    assert np.array_equal(got, ref)
    assert (got[~np.isfinite(d)] == 0).all()
    if d_range[1] - d_range[0] > 1:
        assert len(np.unique(got.reshape(-1, 3), axis=0)) > 100  # the whole map in use, not one colour


@pytest.mark.parametrize("doffs", [0.0, -2.5])
def test_the_compiled_depth_planes_are_numpys(
    computed: tuple[Grid, dict[str, DepthResult]], monkeypatch: pytest.MonkeyPatch, doffs: float
) -> None:
    """Issue 24, the write: 1/Z and the NUKE disparity layers made in one compiled pass are the numpy path's
    bit for bit, in the same order, on a row of cameras (left and right layers) and a grid (and the vertical
    one), at every kind of disparity: none (inf, NaN), negative, zero of both signs, where d + doffs <= 0, where
    Z overflows, and huge."""
    grid, results = computed
    specials = np.array(
        [np.inf, -np.inf, np.nan, -1.0, 0.0, -0.0, 1e-45, 2.5, 2.5000002, 1e30, -3e38, 7.25], np.float32
    )
    rng = np.random.default_rng(4)
    for offsets in (grid.offsets, {c: (float(i % 2), float(i // 2)) for i, c in enumerate(CAMS)}):
        g = dataclasses.replace(grid, offsets=offsets, doffs=doffs)
        for cam in CAMS:
            d = rng.uniform(-5, 12, (H, W)).astype(np.float32)
            d.reshape(-1)[: specials.size * 50] = np.tile(specials, 50)
            res = dataclasses.replace(results[cam], disparity=d)
            monkeypatch.setattr(export, "COMPILED", True)
            got = export.depth_channels(g, cam, res)
            monkeypatch.setattr(export, "COMPILED", False)
            want = export.depth_channels(g, cam, res)
            assert list(got) == list(want)
            for k in want:
                assert got[k].dtype == np.float32 and np.array_equal(got[k].view(np.uint32), want[k].view(np.uint32)), k
            assert ("disparityV.y" in want) == (offsets is not grid.offsets)
