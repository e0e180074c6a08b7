"""The conversion between our rectified camera frame and MIV's (rigctl.interop.miv): axes, principal point,
depth coding; checked by projecting points both ways."""

from __future__ import annotations

import numpy as np
import pytest

from rigctl.interop.miv import camera_entry, cv_to_omaf, depth_levels, levels_disparity, omaf_to_cv
from rigctl.interop.miv_import import rotation


def test_axes_round_trip_and_name_the_right_directions() -> None:
    p = np.array([[0.3, -0.2, 2.5], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    q = cv_to_omaf(p)
    assert np.allclose(omaf_to_cv(q), p)
    assert q[1].tolist() == [0.0, -1.0, -0.0]  # our right is MIV's -y (y is left)
    assert q[2].tolist() == [0.0, -0.0, -1.0]  # our down is MIV's -z (z is up)
    assert q[3].tolist() == [1.0, -0.0, -0.0]  # our forward is MIV's x


def test_a_point_projects_to_the_same_pixel_in_both_conventions() -> None:
    f, cx, cy = 1838.2, 479.5, 269.5  # OpenCV: pixel centres on integers
    entry = camera_entry("r1c1", np.zeros(3), (960, 540), f, (cx, cy), (1.0, 5.0))
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-0.6, 0.6, 50), rng.uniform(1.5, 4, 50)])
    u_cv, v_cv = f * pts[:, 0] / pts[:, 2] + cx, f * pts[:, 1] / pts[:, 2] + cy
    x, y, z = cv_to_omaf(pts).T  # MIV: u = -fx y / x + cx, v = -fy z / x + cy, centres at j + 0.5
    (fx, fy), (px, py) = entry["Focal"], entry["Principle_point"]
    u_miv, v_miv = -fx * y / x + px, -fy * z / x + py
    assert np.abs(u_miv - (u_cv + 0.5)).max() < 1e-9
    assert np.abs(v_miv - (v_cv + 0.5)).max() < 1e-9


def test_yaw_pitch_roll_turn_the_way_miv_says() -> None:
    assert np.allclose(rotation(90, 0, 0) @ [1, 0, 0], [0, 1, 0])  # +yaw turns the view left
    assert np.allclose(rotation(0, 90, 0) @ [1, 0, 0], [0, 0, -1])  # +pitch tilts it down
    assert np.allclose(rotation(0, 0, 90) @ [0, 1, 0], [0, 0, 1])  # +roll lifts its left axis


def test_depth_codes_nearest_as_the_top_level_and_none_as_zero() -> None:
    f, b, near, far = 1000.0, 0.1, 2.0, 4.0
    d = np.array([f * b / 2.0, f * b / 4.0, f * b / 3.0, np.inf, -1.0], np.float32)
    levels = depth_levels(d, f, b, near, far)
    assert levels[0] == 65535 and levels[1] == 1 and levels[3] == 0 and levels[4] == 0
    assert levels[2] == round(65535 * (1 / 3 - 1 / 4) / (1 / 2 - 1 / 4))
    back = levels_disparity(levels, f, b, near, far)
    assert back[0] == pytest.approx(d[0], rel=1e-6) and np.isinf(back[3]) and np.isinf(back[4])
    assert back[2] == pytest.approx(d[2], abs=(f * b) * 0.5 * (1 / 2 - 1 / 4) / 65535 + 1e-5)
    assert levels_disparity(np.array([1]), f, b, near, 1000.0)[0] == pytest.approx(f * b / near / 65535)
