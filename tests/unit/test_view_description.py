"""The viewer's guard on take.json (``viewer.bundle._not_finite``): JSON has no inf or NaN, so a description
holding one must be refused, naming where; the grid and take readers refuse the inputs that made one, and this
stays behind them for any other way a number could overflow."""

from __future__ import annotations

import math

from rigctl.viewer.bundle import _not_finite


def test_the_first_number_that_is_not_finite_is_named_by_camera() -> None:
    info = {
        "fps": 25.0,
        "cameras": [{"name": "r0c0", "offset": [0.0, 0.0]}, {"name": "r1c0", "offset": [0.0, math.inf]}],
    }
    assert _not_finite(info) == "cameras[r1c0].offset[1]"
    info["fps"] = math.nan
    assert _not_finite(info) == "fps"


def test_finite_descriptions_and_other_values_pass() -> None:
    assert _not_finite({"cameras": [{"name": "r0c0", "offset": [0.5, -1e300]}], "title": "inf", "n": 3}) is None
    assert _not_finite([]) is None and _not_finite(1.0) is None
