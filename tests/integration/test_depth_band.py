"""Issue 24, coarse to fine: after a quarter-scale integer sweep (a range of more than 64 levels: the rig's
presenter from 1920x1080 up), a band of +-3 px at half scale, then +-1 px at full resolution
(``costvolume.band``), instead of +-3 px at full resolution. Measured against the path without it
(``costvolume.BAND`` off, the reference) on the realistic presenter rendered at 1920x1080 and on the
stratified scenes over a range 60 px wider than they need on each side."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np
import pytest

import rigctl.depth.costvolume as costvolume
from rigctl.depth.estimate import estimate
from rigctl.depth.grid import Grid
from rigctl.depth.presets import PRESETS
from rigctl.depth.scenes import SCENES
from rigctl.keying import Keyer
from rigctl.simulated_presenter import presenter

THRESHOLDS = (0.1, 0.2, 0.5, 1.0, 2.0)


def bad(
    grid: Grid,
    cam: str,
    d_range: tuple[float, float],
    band: bool,
    monkeypatch: pytest.MonkeyPatch,
    *,
    keyer: Keyer | None,
    border: int = 0,
) -> tuple[dict[float, float], dict]:
    monkeypatch.setattr(costvolume, "BAND", band)
    r = estimate(grid, cam, d_range, PRESETS["best"], keyer=keyer)
    assert grid.truth is not None
    truth = grid.truth[cam]
    inner = np.zeros(truth.shape, bool)
    inner[border : truth.shape[0] - border, border : truth.shape[1] - border] = True
    inner &= np.isfinite(truth)
    d = r.disparity[inner]
    err = np.where(np.isfinite(d), np.abs(d - truth[inner]), np.inf)  # no estimate counts as bad
    return {t: float(np.mean(~(err <= t)) * 100) for t in THRESHOLDS}, dict(r.stats)


@pytest.fixture(scope="module")
def presenter_1080(tmp_path_factory: pytest.TempPathFactory) -> tuple[Grid, tuple[float, float]]:
    """The realistic simulated presenter rendered at the rig's 1920x1080 (the shipped sim rig at twice the
    pixels: the same geometry), its true disparity the truth."""
    text = (resources.files("rigctl.rigs") / "sim-3x3.yaml").read_text(encoding="utf-8")
    text = text.replace("width_px: 960", "width_px: 1920").replace("height_px: 540", "height_px: 1080")
    rig = Path(tmp_path_factory.mktemp("rig")) / "sim-1080.yaml"
    rig.write_text(text.replace("name: sim-3x3", "name: sim-3x3-1080"), encoding="utf-8")
    ds = presenter(False, str(rig))
    assert ds.grid.shape == (1080, 1920)
    return ds.grid, ds.d_range


@pytest.mark.parametrize("cam", ["r0c0", "r1c1"])
def test_the_band_at_the_rigs_resolution_is_no_worse_and_evaluates_fewer_levels(
    presenter_1080: tuple[Grid, tuple[float, float]], cam: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    grid, d_range = presenter_1080
    without, s_without = bad(grid, cam, d_range, False, monkeypatch, keyer=Keyer())
    banded, s_band = bad(grid, cam, d_range, True, monkeypatch, keyer=Keyer())
    print(cam, "without the band", without, "with it", banded)
    assert s_without["coarse_scale"] == s_band["coarse_scale"] == 0.25
    assert "band_sweep_pixel_levels" not in s_without and s_band["band_scale"] == costvolume.BAND_SCALE
    assert s_without["fractional_candidates"] == 13 and s_band["fractional_candidates"] == 5
    # the band's levels at half scale and the narrower full-resolution sweep: under 60 % of the levels
    full = s_without["fractional_sweep_pixel_levels"]
    assert s_band["band_sweep_pixel_levels"] + s_band["fractional_sweep_pixel_levels"] < 0.6 * full
    for t in THRESHOLDS:
        assert banded[t] <= without[t] + 0.2, (t, without, banded)
    # and better where it matters to a headset: the sub-pixel part (a smoother start for the fine sweep)
    assert banded[0.2] < without[0.2] - 0.5, (without, banded)


@pytest.mark.parametrize("scene", ["surfaces", "thin"])
def test_the_band_on_wide_ranges_states_its_cost_on_thin_strips(scene: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Slanted surfaces: no worse. Strips one or two pixels wide vanish at half scale, so where their
    disparity lies more than a pixel from what surrounds them only the semi-global pairs find them: up to
    0.6 points more pixels off by 0.5 px or more (0.3 to 0.5 measured), stated here, not hidden."""
    grid = SCENES[scene]((256, 256), 0)
    assert grid.disparity_range is not None
    lo, hi = grid.disparity_range
    wide = (lo - 60.0, hi + 60.0)
    without, _ = bad(grid, "r1c1", wide, False, monkeypatch, keyer=None, border=15)
    banded, stats = bad(grid, "r1c1", wide, True, monkeypatch, keyer=None, border=15)
    print(scene, "without the band", without, "with it", banded)
    assert stats["coarse_scale"] == 0.25 and stats["band_scale"] == 0.5
    allowed = 0.2 if scene == "surfaces" else 0.6
    for t in THRESHOLDS:
        assert banded[t] <= without[t] + allowed, (t, without, banded)
    assert banded[1.0] < 5.0, banded  # both good matches, not equally broken
