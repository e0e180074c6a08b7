"""The temporal stabiliser on real pictures: a 3x3 sub-grid of the HCI light field ``dino`` (stride 3, a crop),
made into frame sets with fresh sensor noise each, a change of exposure, and a textured card moving in front.
There is no truth: the reference is the estimate from the noise-free pictures, and the card's own disparity.
The light field is read in place from the shared data (never copied); a missing folder fails, naming it."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import cv2
import numpy as np
import pytest
from conftest import SHARED

from rigctl.depth.estimate import estimate
from rigctl.depth.grid import Grid, grid_from_arrays
from rigctl.depth.presets import PRESETS
from rigctl.depth.temporal import Temporal

DATA = SHARED / "data" / "hci-training"
VIEWS = {"r0c0": 10, "r0c1": 13, "r0c2": 16, "r1c0": 37, "r1c1": 40, "r1c2": 43, "r2c0": 64, "r2c1": 67, "r2c2": 70}
CROP = (slice(176, 336), slice(176, 336))  # 160 x 160 around the centre
D_RANGE = (-2.5, 4.0)
D_CARD = 3.0  # the card's disparity per view step: in front of everything in dino (-1.7 to 1.8)
CARD = (50, 40)  # height, width



def views(scene: str) -> dict[str, np.ndarray]:
    out = {}
    for n, i in VIEWS.items():
        img = cv2.imread(str(DATA / scene / f"input_Cam{i:03d}.png"))
        assert img is not None, f"{DATA / scene}: view {i} missing (the shared data, read in place)"
        out[n] = img[CROP].astype(np.float32)
    return out


def frame(
    clean: dict[str, np.ndarray],
    rng: np.random.Generator,
    gain: float = 1.0,
    card_x: int | None = None,
    noise: float = 2.0,
) -> Grid:
    """One frame set: the pictures times ``gain``, a textured card at D_CARD with its left edge at ``card_x`` in
    r1c1 (a point at (x, y) with disparity d lies at (x - d dx, y - d dy) in a camera at (dx, dy)), ``noise`` in
    8-bit levels, 8-bit."""
    card = cv2.imread(str(DATA / "cotton" / "input_Cam040.png"))[200 : 200 + CARD[0], 200 : 200 + CARD[1]]
    out = {}
    for n, img in clean.items():
        img = img * gain
        if card_x is not None:
            dx, dy = int(n[3]) - 1, int(n[1]) - 1
            x0, y0 = round(card_x - D_CARD * dx), round(55 - D_CARD * dy)
            img = img.copy()
            img[y0 : y0 + CARD[0], x0 : x0 + CARD[1]] = card
        out[n] = np.clip(np.rint(img + rng.normal(0, noise, img.shape)), 0, 255).astype(np.uint8)
    return grid_from_arrays(out, 1000.0, 1.0, 1.0)


@dataclass
class Run:
    single: list[np.ndarray]
    stable: list[np.ndarray]
    stats: list[dict[str, object]]


def depth(grids: list[Grid]) -> Run:
    temporal, run = Temporal(), Run([], [], [])
    for g in grids:
        res = estimate(g, "r1c1", D_RANGE, PRESETS["best"], keyer=None)
        run.single.append(res.disparity.copy())
        res = temporal.stabilise(g, "r1c1", res, D_RANGE)
        temporal.advance(g, {"r1c1": res})
        run.stable.append(res.disparity)
        run.stats.append(dict(res.stats))
    return run


def mean_change(ds: list[np.ndarray]) -> float:
    return float(np.mean([np.abs(b - a).mean() for a, b in itertools.pairwise(ds)]))


INNER = (slice(8, -8), slice(8, -8))  # every view sees it


@pytest.fixture(scope="module")
def clean() -> dict[str, np.ndarray]:
    return views("dino")


def test_a_still_real_scene_with_noise_and_a_change_of_exposure_stays_still(clean: dict[str, np.ndarray]) -> None:
    rng = np.random.default_rng(0)
    reference = estimate(frame(clean, rng, noise=0.0), "r1c1", D_RANGE, PRESETS["best"], keyer=None).disparity
    run = depth([frame(clean, rng, gain=1.06 if i == 3 else 1.0) for i in range(6)])
    single, stable = mean_change(run.single), mean_change(run.stable)
    assert stable < single / 3, (single, stable)
    assert run.stats[3]["temporal_blended_share"] > 0.8, run.stats[3]  # the exposure changed, nothing moved
    err_single = np.abs(run.single[-1] - reference)[INNER].mean()
    err_stable = np.abs(run.stable[-1] - reference)[INNER].mean()
    assert err_stable < err_single, (err_single, err_stable)


def test_a_card_moving_in_front_of_a_real_scene_is_followed_not_dragged(clean: dict[str, np.ndarray]) -> None:
    """The card moves 5 px right per frame: where it is, the depth is the card's; where it was, the scene's
    again; the stabilised depth is as good as the single-frame one there, and steadier everywhere."""
    rng = np.random.default_rng(1)
    xs = [40, 40, 45, 50, 50, 55]
    run = depth([frame(clean, rng, card_x=x) for x in xs])
    for i in range(1, len(xs)):
        on_card = np.zeros(run.stable[i].shape, bool)
        on_card[55 + 4 : 55 + CARD[0] - 4, xs[i] + 4 : xs[i] + CARD[1] - 4] = True
        left = np.zeros_like(on_card)
        if xs[i] != xs[i - 1]:
            left[55 + 4 : 55 + CARD[0] - 4, xs[i - 1] + 1 : xs[i] - 1] = True  # the strip the card uncovered
        for d in (run.single[i], run.stable[i]):
            assert np.median(np.abs(d[on_card] - D_CARD)) < 0.2
        if left.any():
            # the new estimate, or (held) the previous depth within the agreement of it: never the card's depth
            tol = float(run.stats[i]["temporal_agree_px"])  # type: ignore[arg-type]
            assert np.abs(run.stable[i][left] - run.single[i][left]).max() <= tol + 1e-6
            assert np.median(run.stable[i][left]) < D_CARD - 1.5  # the scene behind, not the card
    assert mean_change(run.stable) < mean_change(run.single)
