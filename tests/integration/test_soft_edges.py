"""The subject's soft edge (issue 31): a simulated take with ``edges=soft`` (hair-like strands thinner than a
pixel, every edge pixel integrated from 4x4 rays) records the truth's alpha and unmixed foreground colour, and
the soft key recovers both from the captured 4:2:2 picture far better than the hard key did: alpha SAD and
MSE on the edge band at most half of the hard key's, measured here in the same run, and the unmixed colour
closer to the truth's than the captured (mixed) colour is."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from tests_support import run_rigctl

from rigctl.depth.grid import TakeGrid
from rigctl.depth.matte_scores import matte_scores
from rigctl.imagefile import read_png
from rigctl.keying import Keyer
from rigctl.pfm import read_pfm

CAMERA = "r1c1"


@pytest.fixture(scope="module", params=[False, True], ids=["still", "moving"])
def take(request: pytest.FixtureRequest, module_tmp: Callable[[str], Path]) -> Path:
    """One frame set of the ideal seed-3 presenter with soft edges: still, or moving (the simulator's default:
    its first frame is the first pose, blurred over the exposure)."""
    out = module_tmp("soft")
    res = run_rigctl(
        "record", "--take", "soft", "--frames", "1", "--out", str(out),
        "--sim", "ideal=true", "--sim", "seed=3", "--sim", f"motion={str(request.param).lower()}",
        "--sim", "edges=soft", "--sim", "deterministic=true", "--force",
        timeout=900,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return out / "soft"


def _truth(take: Path, kind: str) -> np.ndarray:
    path = take / "truth" / kind / "000000" / f"{CAMERA}.pfm"
    assert path.is_file(), f"{path} missing: the soft-edge truth was not written"
    return read_pfm(path)


def test_the_truth_holds_a_fractional_alpha_and_the_unmixed_colour(take: Path) -> None:
    alpha, colour = _truth(take, "alpha"), _truth(take, "foreground")
    matte = read_png(take / "truth" / "matte" / "000000" / f"{CAMERA}.png") > 127
    assert alpha.shape == matte.shape and colour.shape == (*matte.shape, 3)
    assert np.isfinite(alpha).all() and np.isfinite(colour).all()
    assert alpha.min() >= 0.0 and alpha.max() <= 1.0
    fractional = (alpha > 0) & (alpha < 1)
    # a binary matte has no fractional pixel; here the whole outline and the strands have them
    assert fractional.sum() > 3000, int(fractional.sum())
    # strands thinner than a pixel: partly covered pixels whose centre misses the subject
    assert int((fractional & ~matte).sum()) > 1000
    assert np.all(colour[alpha == 0] == 0) and colour[alpha > 0].max() > 0.2
    # the picture the camera recorded is the truth's mix: a F + (1 - a) B, B the screen the pixel's
    # neighbours show; checked on the luma, which 4:2:2 keeps per pixel
    rgb = TakeGrid(take).grid(0).images[CAMERA]
    luma = np.array([0.2126, 0.7152, 0.0722], np.float32)
    y, y_f = rgb @ luma, colour @ luma
    screen = alpha == 0
    y_b = float(np.median(y[screen]))
    edge = fractional & (np.abs(y_f - y_b) > 0.1)
    mixed = alpha[edge] * y_f[edge] + (1 - alpha[edge]) * y_b
    assert float(np.median(np.abs(mixed - y[edge]))) < 0.03


def test_the_soft_key_halves_the_hard_keys_alpha_error_and_unmixes_the_colour(take: Path) -> None:
    truth, truth_colour = _truth(take, "alpha"), _truth(take, "foreground")
    rgb = TakeGrid(take).grid(0).images[CAMERA]
    keyer = Keyer()
    hard = matte_scores(keyer.matte(rgb), truth)  # the key every output used before
    key = keyer.soft(rgb)
    soft = matte_scores(key.alpha, truth)
    assert hard["band_pixels"] == soft["band_pixels"] > 5000
    fractional = (truth > 0) & (truth < 1)
    mixed_error = float(np.abs(rgb - truth_colour)[fractional].mean())
    unmixed_error = float(np.abs(key.foreground - truth_colour)[fractional].mean())
    print(
        f"edge band {soft['band_pixels']} px: SAD {hard['sad_k']:.3f}k -> {soft['sad_k']:.3f}k, "
        f"MSE {hard['mse']:.4f} -> {soft['mse']:.4f}, gradient {hard['gradient_k']:.4f}k -> "
        f"{soft['gradient_k']:.4f}k, connectivity {hard['connectivity_k']:.3f}k -> {soft['connectivity_k']:.3f}k; "
        f"foreground colour error on {int(fractional.sum())} partly covered px: captured {mixed_error:.4f}, "
        f"unmixed {unmixed_error:.4f}"
    )
    assert soft["sad_k"] <= 0.5 * hard["sad_k"]
    assert soft["mse"] <= 0.5 * hard["mse"]
    assert unmixed_error < mixed_error
    assert np.isfinite(key.alpha).all() and np.isfinite(key.foreground).all()
    assert key.alpha.min() >= 0 and key.alpha.max() <= 1


def test_the_key_solved_on_the_edge_band_is_the_key_solved_everywhere(take: Path) -> None:
    """Issue 24: the soft key is solved on the subject's edge band, strands followed out to their tips, not on
    every pixel. On every camera of the soft-edged take it is the key solved everywhere but for a few pixels
    (strand tips cut off by the frame's edge, too faint to tell from the screen, and the screen estimate they
    shift), on a small share of the frame, and no further from the truth."""
    truth = _truth(take, "alpha")
    grid = TakeGrid(take).grid(0)
    keyer = Keyer()
    for cam, rgb in grid.images.items():
        band, everywhere = keyer.soft(rgb), keyer.soft(rgb, everywhere=True)
        assert everywhere.solved == rgb.shape[0] * rgb.shape[1]
        assert band.solved < 0.1 * everywhere.solved, (cam, band.solved)  # about 5 % here
        edge = ((everywhere.alpha > 0) & (everywhere.alpha < 1)) | ((band.alpha > 0) & (band.alpha < 1))
        off = np.abs(band.alpha - everywhere.alpha) > 0.01
        # at most 0.42 % here; without following strands out 1.0 %, without the specks as seeds 2.8 %
        assert off.sum() <= 0.008 * edge.sum(), (cam, int(off.sum()), int(edge.sum()))
        # where the subject is at all (its colour is hidden elsewhere), the same colour where the key is
        seen = (band.alpha > 0.1) & ~off
        assert np.abs(band.foreground - everywhere.foreground)[seen].max() < 1e-3, cam
        if cam == CAMERA:
            a, b = matte_scores(band.alpha, truth), matte_scores(everywhere.alpha, truth)
            assert a["sad_k"] <= 1.01 * b["sad_k"] and a["mse"] <= 1.01 * b["mse"], (a, b)
