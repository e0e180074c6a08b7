"""The NUKE disparity layers of a camera (``rigctl.disparity_layers.layers``), made in place (issue 24: no
frame-sized temporaries at the write's peak): each the disparity times its step, signed, bit for bit the
plain numpy expression's; a missing estimate (+inf, NaN) is 0; the constant planes one shared plane."""

from __future__ import annotations

import numpy as np
import pytest

from rigctl.disparity_layers import Steps, layers


@pytest.mark.parametrize("st", [Steps(1.0, 1.0, 0.65), Steps(0.65, 1.3, None), Steps(None, None, 2.0)])
def test_the_layers_are_the_disparity_times_each_step_bit_for_bit(st: Steps) -> None:
    rng = np.random.default_rng(11)
    d = rng.normal(120.0, 90.0, (37, 53)).astype(np.float32)
    d[::5, ::3] = np.inf
    d[1::7, ::4] = np.nan
    d[2::9] = -0.0
    fin = np.where(np.isfinite(d), d, 0.0).astype(np.float32)
    expected: dict[str, np.ndarray] = {}
    if st.right is not None and st.left is not None:
        expected["disparityL.x"] = (-fin * np.float32(st.right)).astype(np.float32)
        expected["disparityR.x"] = (fin * np.float32(st.left)).astype(np.float32)
        expected["disparityL.y"] = expected["disparityR.y"] = np.zeros_like(fin)
    if st.below is not None:
        expected["disparityV.y"] = (-fin * np.float32(st.below)).astype(np.float32)
        expected["disparityV.x"] = np.zeros_like(fin)
    got = layers(d, st)
    assert set(got) == set(expected)
    for name, plane in got.items():
        assert plane.dtype == np.float32 and plane.shape == d.shape
        assert np.array_equal(plane.view(np.uint32), expected[name].view(np.uint32)), name
        assert np.all(np.isfinite(plane))
        assert not np.shares_memory(plane, d)
    zeros = [p for n, p in got.items() if n in ("disparityL.y", "disparityR.y", "disparityV.x")]
    assert all(p is zeros[0] for p in zeros)
    signed = [p for n, p in got.items() if n in ("disparityL.x", "disparityR.x", "disparityV.y")]
    assert not any(np.shares_memory(a, b) for i, a in enumerate(signed) for b in signed[i + 1 :])
