"""The sweep's compiled bookkeeping (``sweep_kernels``) is the numpy form's bit for bit over a run of levels:
ties, levels no view saw (INVALID), costs above the truncation, a NaN, and the best at the first, a middle and
the last level; and ``costvolume.sweep`` gives the same result with either (on the same compiled costs)."""

from __future__ import annotations

import numpy as np
import pytest

import rigctl.depth.costvolume as cvm
from rigctl.depth.cost import INVALID_COST, TRUNCATE
from rigctl.depth.sweep_kernels import truncate_level, update, update_reference


def _state(shape: tuple[int, int]) -> tuple:
    return (
        np.full(shape, np.inf, np.float32),
        np.zeros(shape, np.int32),
        np.full(shape, np.inf, np.float32),
        np.full(shape, np.inf, np.float32),
        np.zeros(shape, np.float32),
        np.zeros(shape, bool),
    )


def _levels(n: int, shape: tuple[int, int]) -> list[np.ndarray]:
    rng = np.random.default_rng(n)
    out = []
    for k in range(n):
        raw = (rng.random(shape) * 1.5 * TRUNCATE).astype(np.float32)
        raw[rng.random(shape) < 0.1] = INVALID_COST  # no view saw it at this level
        raw[:, 0] = np.float32(0.25 * TRUNCATE)  # ties along a column
        raw[0, 1] = np.nan if k == n // 2 else raw[0, 1]
        raw[1, 2] = 0.0 if k == 0 else raw[1, 2]  # best at the first level
        raw[2, 3] = 0.0 if k == n - 1 else raw[2, 3]  # and at the last
        out.append(raw)
    return out


@pytest.mark.parametrize("n", [1, 2, 7])
def test_compiled_bookkeeping_is_the_references_bit_for_bit(n: int) -> None:
    shape = (9, 13)
    got, ref = _state(shape), _state(shape)
    prev_got = np.full(shape, np.inf, np.float32)
    prev_ref = prev_got.copy()
    for k, raw in enumerate(_levels(n, shape)):
        clipped, seen = truncate_level(raw, TRUNCATE, INVALID_COST)
        assert np.array_equal(seen, raw < INVALID_COST * 0.5)
        assert np.array_equal(clipped, np.minimum(raw, TRUNCATE), equal_nan=True)
        c = clipped * np.float32(0.9) + np.float32(0.01)  # the filter's stand-in: any map of the level
        prev_got = update(c.copy(), seen, k, prev_got, got, INVALID_COST, TRUNCATE)
        prev_ref = update_reference(c.copy(), seen, k, prev_ref, ref, INVALID_COST, TRUNCATE)
        assert np.array_equal(prev_got, prev_ref, equal_nan=True)
        for a, b in zip(got, ref, strict=True):
            assert np.array_equal(a, b, equal_nan=True)
    _, k_best, *_ = got
    assert (k_best == n - 1).any() and (k_best == 0).any()


def test_the_sweep_is_the_same_with_either(monkeypatch: pytest.MonkeyPatch) -> None:
    from rigctl.depth.costvolume import MatchViews, VolumeParams, sweep

    rng = np.random.default_rng(3)
    base = rng.random((40, 70, 3)).astype(np.float32)
    images = {"a": base, "b": np.roll(base, -3, axis=1), "c": np.roll(base, 3, axis=1)}
    views = MatchViews(images, "a", {"b": (1.0, 0.0), "c": (-1.0, 0.0)}, (0, 40, 0, 70))
    p = VolumeParams(keep=1)
    levels = [float(v) for v in range(0, 7)]
    compiled = sweep(views, levels, p, p.window, p.radius)
    # the same compiled costs, the bookkeeping by the numpy forms
    monkeypatch.setattr(cvm, "update", update_reference)
    monkeypatch.setattr(cvm, "truncate_level", lambda raw, t, inv: (np.minimum(raw, t), raw < inv * 0.5))
    reference = sweep(views, levels, p, p.window, p.radius)
    for field in ("disparity", "cost", "mean_cost", "bound", "no_view"):
        assert np.array_equal(getattr(compiled, field), getattr(reference, field), equal_nan=True), field
    assert np.isclose(np.median(compiled.disparity), 3.0, atol=0.25)
