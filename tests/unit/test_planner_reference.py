"""Every vector of REFERENCE.md's planner table, against the pure planner functions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rigctl.planning import planner

SP_UHD = 13.056e-3 / 3840  # 3.4 um
F = 25e-3
C0 = F / SP_UHD
BUDGET_PX = 0.04 * 3840


def test_c0_is_focal_length_in_pixels() -> None:
    assert float(planner.c0_px(F, SP_UHD)) == pytest.approx(7352.9, abs=0.05)


def test_paper_minimum_distance() -> None:
    near = float(planner.min_near_m(C0, 0.120, 1.0, BUDGET_PX))
    assert near == pytest.approx(1.948, abs=1e-3)
    # f = 25.03 mm gives the paper's rounded 1.95 m
    c0_paper = float(planner.c0_px(25.03e-3, SP_UHD))
    assert float(planner.min_near_m(c0_paper, 0.120, 1.0, BUDGET_PX)) == pytest.approx(1.950, abs=1e-3)


def test_disparities_in_pixels() -> None:
    assert float(planner.disparity_px(C0, 0.120, 1.95)) == pytest.approx(452.5, abs=0.05)
    assert float(planner.disparity_px(C0, 0.120, 2.95)) == pytest.approx(299.1, abs=0.05)
    p = float(planner.parallax_px(C0, 0.120, 1.95, 2.95))
    assert p == pytest.approx(153.4, abs=0.05)
    assert p / 3840 == pytest.approx(0.0399, abs=5e-5)


def test_rule_is_resolution_independent() -> None:
    c0_hd = float(planner.c0_px(F, 2 * SP_UHD))
    p = float(planner.parallax_px(c0_hd, 0.120, 1.95, 2.95))
    assert p == pytest.approx(76.7, abs=0.05)
    assert p / 1920 == pytest.approx(153.4 / 3840, rel=1e-3)


@pytest.mark.parametrize(("f_mm", "near"), [(12, 1.234), (16, 1.482), (20, 1.701), (35, 2.380)])
def test_other_lenses(f_mm: float, near: float) -> None:
    c0 = float(planner.c0_px(f_mm * 1e-3, SP_UHD))
    assert float(planner.min_near_m(c0, 0.120, 1.0, BUDGET_PX)) == pytest.approx(near, abs=1e-3)


def test_vertical_diagonal_and_outer_pairs() -> None:
    vertical = float(planner.parallax_px(C0, 0.078, 1.95, 2.95))
    assert vertical == pytest.approx(99.7, abs=0.05)
    assert vertical / 3840 == pytest.approx(0.026, abs=5e-4)
    assert vertical / 2160 == pytest.approx(0.046, abs=5e-4)
    diag_b = math.hypot(0.120, 0.078)
    assert diag_b == pytest.approx(0.1431, abs=1e-4)
    diagonal = float(planner.parallax_px(C0, diag_b, 1.95, 2.95))
    assert diagonal == pytest.approx(182.9, abs=0.05)
    assert diagonal / 3840 == pytest.approx(0.048, abs=5e-4)
    outer = float(planner.parallax_px(C0, 0.240, 1.95, 2.95))
    assert outer / 3840 == pytest.approx(0.08, abs=5e-4)


def test_stereo_base_formula_with_infinity_in_view() -> None:
    # B = P / (F * (1/n - 1/m)): P = 1.2 mm on the sensor, F = 50 mm, n = 2 m, m = infinity.
    # In pixels: any pitch works, since P / s_p pixels against C0 = F / s_p.
    pitch = 5e-6
    c0 = float(planner.c0_px(50e-3, pitch))
    b = float(planner.max_spacing_m(c0, 2.0, math.inf, 1.2e-3 / pitch))
    assert b == pytest.approx(0.048, rel=1e-12)


def test_depth_error() -> None:
    dz = float(planner.depth_error_m(7353, 0.12, 2.0, 0.25))
    assert dz == pytest.approx(1.13e-3, abs=0.005e-3)


def test_light_field_sampling_limit() -> None:
    spacing = float(planner.max_spacing_m(C0, 1.95, 2.95, 1.0))
    assert spacing == pytest.approx(0.78e-3, abs=0.005e-3)
    assert 0.120 / spacing == pytest.approx(150, rel=0.03)


def test_quadratic_root_satisfies_the_quadratic() -> None:
    a = C0 * 0.120 / BUDGET_PX
    for depth in (1e-9, 1e-3, 1.0, 1e3, 1e9):
        near = float(planner.near_for_scale(a, depth))
        residual = near * near + depth * near - a * depth
        assert abs(residual) <= 1e-12 * max(near * near, depth * near, a * depth)


def test_vectorised_matches_scalar() -> None:
    rng = np.random.default_rng(3)
    c0 = rng.uniform(100, 1e4, 50)
    b = rng.uniform(0.01, 1, 50)
    d = rng.uniform(0.01, 10, 50)
    vec = planner.min_near_m(c0, b, d, 150.0)
    for i in range(50):
        assert vec[i] == float(planner.min_near_m(c0[i], b[i], d[i], 150.0))


def test_field_of_view_and_fit() -> None:
    hfov = float(planner.field_of_view_deg(13.056e-3, F))
    assert hfov == pytest.approx(2 * math.degrees(math.atan(13.056 / 50)), rel=1e-12)
    view = float(planner.view_extent_m(13.056e-3, F, 2.0))
    assert view == pytest.approx(13.056e-3 * 2.0 / F)
    assert bool(planner.fits_every_view(0.6, 0.24, view))  # 0.3 + 0.12 <= 0.52
    assert not bool(planner.fits_every_view(0.9, 0.24, view))
