"""Numerical stability of the planner, by property tests over the whole physical range."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from rigctl.errors import ParameterError
from rigctl.planning import planner

focal = st.floats(1e-3, 1.0)  # 1 mm to 1000 mm
pitch = st.floats(0.5e-6, 50e-6)  # 0.5 um to 50 um
spacing = st.floats(1e-6, 10.0)  # 1 um to 10 m
distance = st.floats(0.01, 1e4)  # 1 cm to 10 km
depth = st.floats(0.0, 1e4) | st.just(math.inf)
budget_px = st.floats(0.5, 2000.0)


@given(focal, pitch, spacing, depth, budget_px)
def test_solve_then_evaluate_returns_the_budget(f: float, sp: float, b: float, d: float, bpx: float) -> None:
    c0 = float(planner.c0_px(f, sp))
    near = float(planner.min_near_m(c0, b, d, bpx))
    assert math.isfinite(near) and near >= 0
    if near == 0:  # a flat subject (or one so thin it underflows) needs no distance at all
        assert d == 0 or d < 1e-300 * c0 * b / bpx
        return
    got = float(planner.subject_parallax_px(c0, b, near, d))
    assert got == pytest.approx(bpx, rel=1e-9)


@given(focal, pitch, spacing, distance, distance)
def test_parallax_is_finite_and_non_negative(f: float, sp: float, b: float, z1: float, z2: float) -> None:
    near, far = min(z1, z2), max(z1, z2)
    c0 = float(planner.c0_px(f, sp))
    p = float(planner.parallax_px(c0, b, near, far))
    assert math.isfinite(p) and p >= 0
    p_inf = float(planner.parallax_px(c0, b, near, math.inf))
    assert math.isfinite(p_inf) and p_inf >= p * (1 - 1e-12)


@given(focal, pitch, spacing, distance, st.floats(0.0, 1e4), st.floats(1.0001, 10.0))
def test_parallax_monotonic_in_spacing_focal_and_depth(
    f: float, sp: float, b: float, near: float, d: float, k: float
) -> None:
    c0 = float(planner.c0_px(f, sp))
    base = float(planner.subject_parallax_px(c0, b, near, d))
    assert float(planner.subject_parallax_px(c0, b * k, near, d)) >= base
    assert float(planner.subject_parallax_px(float(planner.c0_px(f * k, sp)), b, near, d)) >= base
    assert float(planner.subject_parallax_px(c0, b, near, d * k)) >= base
    assert float(planner.subject_parallax_px(c0, b, near, math.inf)) >= base


@given(focal, pitch, spacing, budget_px, st.floats(1e-12, 1e-3))
def test_min_near_continuous_as_depth_goes_to_zero(f: float, sp: float, b: float, bpx: float, d: float) -> None:
    c0 = float(planner.c0_px(f, sp))
    a = c0 * b / bpx
    near = float(planner.min_near_m(c0, b, d, bpx))
    assert float(planner.min_near_m(c0, b, 0.0, bpx)) == 0.0
    # near / sqrt(a*D) = 1 - x/2 + x^2/8 - ... with x = sqrt(D/a): for D << a it goes to zero continuously
    # like sqrt(a*D), with no jump at D = 0
    assume(d < 1e-3 * a)
    assert near == pytest.approx(math.sqrt(a * d) - d / 2, rel=d / a)
    assert 0 < near <= math.sqrt(a * d)


@given(focal, pitch, spacing, budget_px, st.floats(0.01, 1e4))
def test_min_near_monotonic_in_depth_and_bounded_by_infinity(
    f: float, sp: float, b: float, bpx: float, d: float
) -> None:
    c0 = float(planner.c0_px(f, sp))
    n1 = float(planner.min_near_m(c0, b, d, bpx))
    n2 = float(planner.min_near_m(c0, b, d * 2, bpx))
    n_inf = float(planner.min_near_m(c0, b, math.inf, bpx))
    assert n1 <= n2 * (1 + 1e-12) <= n_inf * (1 + 1e-9)
    assert n_inf == pytest.approx(c0 * b / bpx, rel=1e-12)


@given(focal, pitch, distance, st.floats(0.0, 1e4), budget_px)
def test_max_spacing_inverts_parallax(f: float, sp: float, near: float, extra: float, bpx: float) -> None:
    c0 = float(planner.c0_px(f, sp))
    far = near + extra
    b = float(planner.max_spacing_m(c0, near, far, bpx))
    if far == near:
        assert b == math.inf  # no parallax, no limit: reported as unbounded, never NaN
        return
    assert math.isfinite(b) and b > 0
    assert float(planner.parallax_px(c0, b, near, far)) == pytest.approx(bpx, rel=1e-9)


def test_near_equals_far_is_zero_parallax() -> None:
    assert float(planner.parallax_px(7353.0, 0.12, 2.0, 2.0)) == 0.0


@pytest.mark.parametrize(
    ("func", "kwargs", "name"),
    [
        (planner.parallax_px, {"c0": 0.0, "baseline_m": 0.1, "near_m": 1, "far_m": 2}, "c0_px"),
        (planner.parallax_px, {"c0": 7e3, "baseline_m": -0.1, "near_m": 1, "far_m": 2}, "baseline_m"),
        (planner.parallax_px, {"c0": 7e3, "baseline_m": 0.1, "near_m": math.nan, "far_m": 2}, "near_m"),
        (planner.parallax_px, {"c0": 7e3, "baseline_m": 0.1, "near_m": 3, "far_m": 2}, "far_m"),
        (
            planner.parallax_px,
            {"c0": 7e3, "baseline_m": 0.1, "near_m": math.inf, "far_m": math.inf},
            "near_m",
        ),
        (
            planner.min_near_m,
            {"c0": 7e3, "baseline_m": 0.1, "subject_depth_m": -1, "max_parallax_px": 9},
            "subject_depth_m",
        ),
        (
            planner.min_near_m,
            {"c0": 7e3, "baseline_m": 0.1, "subject_depth_m": 1, "max_parallax_px": 0},
            "max_parallax_px",
        ),
        (planner.c0_px, {"focal_length_m": 0.025, "pixel_pitch_m": math.nan}, "pixel_pitch_m"),
        (
            planner.depth_error_m,
            {"focal_px": 7e3, "baseline_m": 0, "distance_m": 2, "disparity_error_px": 1},
            "baseline_m",
        ),
    ],
)
def test_bad_inputs_are_refused_by_name(func, kwargs, name) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ParameterError, match=name):
        func(**kwargs)


def test_bad_value_in_an_array_is_located() -> None:
    with pytest.raises(ParameterError, match=r"index 2"):
        planner.parallax_px(7e3, np.array([0.1, 0.2, -0.3]), 1.0, 2.0)
