"""The sweep's compiled bookkeeping (``sweep_kernels``) is the numpy form's bit for bit over a run of levels:
ties, levels no view saw (INVALID), costs above the truncation, a NaN, and the best at the first, a middle and
the last level; the compiled finish (the parabola, the mean, the bounds) is ``finish_reference``'s on states
with every kind of pixel; and ``costvolume.sweep`` gives the same result with either (on the same compiled costs)."""

from __future__ import annotations

import numpy as np
import pytest

import rigctl.depth.costvolume as cvm
from rigctl.depth.cost import INVALID_COST, TRUNCATE
from rigctl.depth.sweep_kernels import finish, truncate_level, update, update_reference


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
    monkeypatch.setattr(cvm, "_base_and_offsets", lambda candidates: None)  # the finish by finish_reference
    reference = sweep(views, levels, p, p.window, p.radius)
    for field in ("disparity", "cost", "mean_cost", "bound", "no_view"):
        assert np.array_equal(getattr(compiled, field), getattr(reference, field), equal_nan=True), field
    assert np.isclose(np.median(compiled.disparity), 3.0, atol=0.25)


def _finished_state(n: int, shape: tuple[int, int], seed: int) -> tuple:
    """A sweep's state after ``n`` levels with every case the finish meets: neighbours' costs missing (inf),
    unseen (INVALID), a flat or a concave parabola (its denominator 0, negative, or about 1e-9), the best at
    either end, and nothing seen."""
    rng = np.random.default_rng(seed)
    best = (rng.random(shape) * TRUNCATE).astype(np.float32)
    k_best = rng.integers(0, n, shape).astype(np.int32)
    c_minus = (best + rng.random(shape).astype(np.float32) * np.float32(0.3)).astype(np.float32)
    c_plus = (best + rng.random(shape).astype(np.float32) * np.float32(0.3)).astype(np.float32)
    total = (rng.random(shape) * n * TRUNCATE).astype(np.float32)
    seen_any = rng.random(shape) > 0.1
    c_minus[rng.random(shape) < 0.1] = np.inf
    c_plus[rng.random(shape) < 0.1] = INVALID_COST
    flat = rng.random(shape) < 0.1
    c_minus[flat], c_plus[flat] = best[flat], best[flat]
    concave = rng.random(shape) < 0.05
    c_minus[concave] = best[concave] - np.float32(0.1)
    tiny = rng.random(shape) < 0.05  # denominators about 1e-9 either side of the test
    c_minus[tiny], best[tiny] = np.float32(0.0), np.float32(0.0)
    c_plus[tiny] = (rng.random(int(tiny.sum())) * 2e-9).astype(np.float32)
    best[rng.random(shape) < 0.05] = INVALID_COST
    k_best[0, :3] = (0, n - 1, n // 2)
    return best, k_best, c_minus, c_plus, total, seen_any


@pytest.mark.parametrize("n", [1, 2, 3, 13])
@pytest.mark.parametrize("around", [False, True])
def test_compiled_finish_is_the_references_bit_for_bit(n: int, around: bool) -> None:
    shape = (31, 47)
    state = _finished_state(n, shape, seed=n)
    if around:
        base = (np.random.default_rng(1).random(shape) * 300).astype(np.float32)
        candidates: object = cvm.Around(base, 0.25, n // 2) if n % 2 else cvm.Around(base, 0.5, n // 2)
        given = (base, candidates.offsets)  # type: ignore[attr-defined]
    else:
        candidates = [float(v) for v in np.arange(-n, n, 2.0)[:n] * 0.75 + 148.0]
        given = (None, np.asarray(candidates, np.float32))
    ref = cvm.finish_reference(candidates, tuple(a.copy() for a in state))  # type: ignore[arg-type]
    disp, mean, bound, no_view = finish(state, *given, INVALID_COST)
    assert np.array_equal(disp, ref.disparity, equal_nan=True)
    assert np.array_equal(mean, ref.mean_cost, equal_nan=True)
    assert np.array_equal(bound, ref.bound) and np.array_equal(no_view, ref.no_view)
    assert disp.dtype == np.float32 and mean.dtype == np.float32
    if n > 2:  # the parabola moved some pixels off their candidate, by at most half a step
        k = state[1]
        at = ref.disparity - (given[1][k] + (given[0] if given[0] is not None else 0))
        assert (at != 0).any() and np.abs(at).max() <= 0.5 * np.abs(np.diff(given[1])).max() + 1e-4
