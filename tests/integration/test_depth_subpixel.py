"""Depth on light-field-like input: the default engine against the semi-global pairs on the stratified scenes
(sub-pixel error, pixel locking), the metrics, stability at the edges of the input space, and the grid
shapes and failures a user can hand the CLI."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from tests_support import run_rigctl

from rigctl.depth.estimate import estimate
from rigctl.depth.grid import grid_from_arrays
from rigctl.depth.grid_folder import load_grid_folder
from rigctl.depth.metrics import locking, score
from rigctl.depth.presets import PRESETS
from rigctl.depth.scenes import SCENES, write_grid_folder
from rigctl.errors import RigFileError


@pytest.mark.parametrize("scene", list(SCENES))
def test_best_halves_sub_pixel_error_and_does_not_lock_on_stratified_scenes(scene: str) -> None:
    g = SCENES[scene]((256, 256))
    t = g.truth["r1c1"]  # type: ignore[index]
    mask = np.zeros(t.shape, bool)
    mask[15:-15, 15:-15] = True
    assert g.disparity_range is not None
    fig = {}
    for p in ("best", "pairs"):
        d = estimate(g, "r1c1", g.disparity_range, PRESETS[p], keyer=None).disparity
        fig[p] = score(d, t, mask)
    assert fig["best"]["bad_0.2"] <= 0.5 * fig["pairs"]["bad_0.2"], fig
    assert fig["best"]["locking_pct"] < 10 and fig["best"]["locking_pct"] < 0.5 * fig["pairs"]["locking_pct"], fig


def test_scenes_have_fractional_mixed_sign_truth_and_round_trip_as_grid_folders(tmp_path: Path) -> None:
    g = SCENES["surfaces"]((64, 64))
    t = g.truth["r1c1"]  # type: ignore[index]
    assert t.min() < 0 < t.max()
    frac = np.mod(t, 1.0)
    assert np.histogram(frac, 4, (0, 1))[0].min() > 0.1 * t.size  # fractional values spread over the pixel
    back = load_grid_folder(write_grid_folder(g, tmp_path / "grid"))
    assert back.names == g.names and back.disparity_range == g.disparity_range
    assert back.offsets["r2c1"] == pytest.approx(g.offsets["r2c1"])
    assert np.abs(back.images["r0c0"] - g.images["r0c0"]).max() <= 0.5 / 255 + 1e-6
    assert (tmp_path / "grid" / "truth" / "r1c1.pfm").exists()


def test_a_16_bit_picture_with_alpha_reads_as_its_colour_in_a_grid_folder(tmp_path: Path) -> None:
    """16-bit BGRA was reversed whole and then cut to three channels: (A, R, G) read as (R, G, B)."""
    g = SCENES["surfaces"]((32, 32))
    folder = write_grid_folder(g, tmp_path / "grid")
    bgr = cv2.imread(str(folder / "r0c0.png"))
    cv2.imwrite(str(folder / "r0c0.png"), cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA).astype(np.uint16) * 257)
    back = load_grid_folder(folder)
    assert np.abs(back.images["r0c0"] - bgr[..., ::-1] / np.float32(255)).max() < 1e-6


def test_locking_figure_sees_rounded_estimates_and_not_noisy_ones() -> None:
    rng = np.random.default_rng(0)
    truth = rng.uniform(-5, 5, 20000)
    assert locking(np.round(truth), truth) > 80
    assert locking(truth + rng.normal(0, 0.05, truth.size), truth) < 5
    s = score(np.full((4, 4), np.inf, np.float32), np.zeros((4, 4), np.float32), np.ones((4, 4), bool))
    assert s["bad_0.1"] == 100 and s["mae_px"] is None and s["locking_pct"] is None


def _slanted(h: int, w: int, a: float, b: float, rows: int = 3, cols: int = 3) -> tuple[dict, np.ndarray]:  # type: ignore[type-arg]
    """A slanted textured plane d(x) = a + b x seen exactly by every camera (built from the scene renderer)."""
    from rigctl.depth.scenes import Layer, render, texture, truth_of

    rng = np.random.default_rng(3)
    layer = Layer(lambda x, y: (a + b * x + 0 * y).astype(np.float32), texture(rng, (h + 64, w + 64), [(1.0, 0.2)]))
    images = {}
    for r in range(rows):
        for c in range(cols):
            images[f"r{r}c{c}"] = render([layer], (h, w), (c - (cols - 1) / 2, (r - (rows - 1) / 2) * 0.65), 32)
    return images, truth_of([layer], (h, w))


def test_mixed_sign_slanted_plane_and_ranges_from_one_to_hundreds_of_levels() -> None:
    images, t = _slanted(64, 96, -3.3, 0.07)  # -3.3 .. +3.3 px
    g = grid_from_arrays(images, 1000.0, 1.0, 0.65)
    # one engine for both: a narrow range swept at full resolution, a range of 420 levels coarse to fine
    for rng, tol in (((-5.0, 5.0), 0.15), ((-20.0, 400.0), 0.5)):
        d = estimate(g, "r1c1", rng, PRESETS["best"], keyer=None).disparity
        assert np.all(np.isfinite(d[8:-8, 8:-8]))
        assert np.median(np.abs(d - t)[8:-8, 8:-8]) < tol, rng
    d = estimate(g, "r1c1", (0.0, 0.0), PRESETS["best"], keyer=None).disparity  # one level: a bounded answer
    assert not np.isnan(d).any() and np.abs(d[np.isfinite(d)]).max() <= 1.0


@pytest.mark.parametrize("kind", ["constant", "saturated", "periodic", "one_row", "one_pixel"])
def test_degenerate_images_give_finite_or_flagged_never_nan(kind: str) -> None:
    h, w = {"one_row": (1, 64), "one_pixel": (1, 1)}.get(kind, (48, 64))
    x = np.arange(w, dtype=np.float32)[None, :].repeat(h, 0)
    base = {
        "constant": np.full((h, w), 0.4),
        "saturated": np.ones((h, w)),
        "periodic": 0.5 + 0.4 * np.sin(x * 2 * np.pi / 4),
    }
    img = base.get(kind, np.random.default_rng(1).random((h, w))).astype(np.float32)
    g = grid_from_arrays({f"r{r}c{c}": np.roll(img, -c, axis=1) for r in range(3) for c in range(3)}, 10.0, 1.0, 1.0)
    r = estimate(g, "r1c1", (-3.0, 6.0), PRESETS["best"], keyer=None)
    assert not np.isnan(r.disparity).any() and not np.isnan(r.confidence).any()
    if kind in ("constant", "saturated"):
        assert r.unreliable[np.isfinite(r.disparity)].all() and r.confidence.max() == 0.0


def test_a_camera_that_sees_nothing_of_the_subject_is_flagged() -> None:
    images, _ = _slanted(40, 60, 2.0, 0.0)
    g = grid_from_arrays(images, 1000.0, 1.0, 0.65)
    r = estimate(g, "r1c1", (200.0, 210.0), PRESETS["best"], keyer=None)  # every view lies outside its image
    assert not np.isnan(r.disparity).any()
    assert np.isinf(r.disparity).all() and r.confidence.max() == 0.0


def test_a_grid_with_a_gap_is_matched(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.random((64, 200)).astype(np.float32), (0, 0), 1.0)
    images = {"r0c0": img[:, :80], "r0c5": img[:, 15:95]}  # disparity 3 per step: 15 px over five steps
    g = grid_from_arrays(images, 100.0, 1.0, 1.0)
    for p in PRESETS:
        d = estimate(g, "r0c0", (0.0, 20.0), PRESETS[p], keyer=None).disparity
        assert not np.isnan(d).any()
    d = estimate(g, "r0c0", (0.0, 20.0), PRESETS["best"], keyer=None).disparity
    assert np.median(np.abs(d[8:-8, 8:60] - 3.0)) < 0.2


def test_cli_names_size_mismatch_gap_and_nothing_to_estimate(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    img = (rng.random((64, 120, 3)) * 255).astype(np.uint8)
    spec = "spacing_x: 1.0\nspacing_y: 1.0\nfocal_px: 100\ndisparity_range_px: [0, 20]\n"
    one = tmp_path / "one"
    one.mkdir()
    cv2.imwrite(str(one / "r0c0.png"), img)
    (one / "grid.yaml").write_text(spec)
    res = run_rigctl("depth", str(one), "--out", str(tmp_path / "o1"))
    assert res.returncode != 0 and "no depth could be estimated" in res.stderr and "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    cv2.imwrite(str(one / "r0c1.png"), img[:60])
    with pytest.raises(RigFileError, match=r"r0c1.png: image is 120x60, but r0c0.png is 120x64"):
        load_grid_folder(one)
    res = run_rigctl("depth", str(one), "--out", str(tmp_path / "o2"))
    assert res.returncode != 0 and "r0c1.png" in res.stderr and "sizes differ" in res.stderr
    gap = tmp_path / "gap"
    gap.mkdir()
    cv2.imwrite(str(gap / "r0c0.png"), img)
    cv2.imwrite(str(gap / "r0c5.png"), np.roll(img, -10, axis=1))
    (gap / "grid.yaml").write_text(spec)
    res = run_rigctl("depth", str(gap), "--out", str(tmp_path / "o3"), "--no-key")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "o3" / "r0c0.exr").exists() and (tmp_path / "o3" / "r0c5.exr").exists()
