"""The winner-take-all sweep's per-level bookkeeping as two compiled passes (issue 24): before the guided
filter, the level's cost truncated and where a view saw it; after it, the running best, its level, the costs
of its two neighbouring levels (for the parabola), the running total and where any view saw the point.

Each level took about a dozen frame-sized numpy passes (masks, ``copyto`` with ``where``, boolean writes);
these are two, the same arithmetic in the same order, so the same bits (``update_reference`` is the numpy form
``costvolume.sweep`` ran, ``tests/unit/test_sweep_kernels.py`` holds the two to identical results). After the
last level, ``finish`` makes the result (the parabola's sub-step, the mean cost, the bounds) in one pass.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # waiting threads sleep (see rigctl/render/kernels.py)

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@njit(parallel=True, cache=True, fastmath=False)
def _truncate(raw: F32, truncate: np.float32, invalid_half: np.float32, clipped: F32, seen: NDArray[np.bool_]) -> None:
    for y in prange(raw.shape[0]):
        for x in range(raw.shape[1]):
            v = raw[y, x]
            seen[y, x] = v < invalid_half
            clipped[y, x] = v if (v < truncate or np.isnan(v)) else truncate  # np.minimum: NaN stays


def truncate_level(raw: F32, truncate: float, invalid: float) -> tuple[F32, NDArray[np.bool_]]:
    """``np.minimum(raw, truncate)`` (contiguous float32, for the filter) and ``raw < invalid / 2`` (a view saw
    the point), in one pass."""
    raw = np.ascontiguousarray(raw, np.float32)
    clipped = np.empty(raw.shape, np.float32)
    seen = np.empty(raw.shape, np.bool_)
    _truncate(raw, np.float32(truncate), np.float32(invalid * 0.5), clipped, seen)
    return clipped, seen


@njit(parallel=True, cache=True, fastmath=False)
def _update(
    c: F32,
    seen: NDArray[np.bool_],
    k: int,
    invalid: np.float32,
    truncate: np.float32,
    prev: F32,
    best: F32,
    k_best: NDArray[np.int32],
    c_minus: F32,
    c_plus: F32,
    total: F32,
    seen_any: NDArray[np.bool_],
) -> None:
    inf = np.float32(np.inf)
    for y in prange(c.shape[0]):
        for x in range(c.shape[1]):
            s = seen[y, x]
            v = c[y, x] if s else invalid
            c[y, x] = v
            if k_best[y, x] == k - 1:  # the level right after the current best
                c_plus[y, x] = v
            b = best[y, x]
            if v < b:
                k_best[y, x] = k
                c_minus[y, x] = prev[y, x]
                c_plus[y, x] = inf
            best[y, x] = b if (b <= v or np.isnan(b)) else v  # np.minimum: NaN wins
            total[y, x] += v if (v < truncate or np.isnan(v)) else truncate
            seen_any[y, x] = seen_any[y, x] or s


def update(
    c: F32,
    seen: NDArray[np.bool_],
    k: int,
    prev: F32,
    state: tuple[F32, NDArray[np.int32], F32, F32, F32, NDArray[np.bool_]],
    invalid: float,
    truncate: float,
) -> F32:
    """Level ``k``'s filtered cost ``c`` (INVALID written where no view saw it, in place) into the ``state``
    (best, k_best, c_minus, c_plus, total, seen_any), ``prev`` the level before's; returns ``c`` as the next
    level's ``prev``."""
    best, k_best, c_minus, c_plus, total, seen_any = state
    c = np.ascontiguousarray(c, np.float32)
    _update(
        c,
        np.ascontiguousarray(seen),
        k,
        np.float32(invalid),
        np.float32(truncate),
        np.ascontiguousarray(prev, np.float32),
        best,
        k_best,
        c_minus,
        c_plus,
        total,
        seen_any,
    )
    return c


def update_reference(
    c: F32,
    seen: NDArray[np.bool_],
    k: int,
    prev: F32,
    state: tuple[F32, NDArray[np.int32], F32, F32, F32, NDArray[np.bool_]],
    invalid: float,
    truncate: float,
) -> F32:
    """:func:`update` in numpy (the form the sweep ran before, kept as the reference)."""
    best, k_best, c_minus, c_plus, total, seen_any = state
    c[~seen] = np.float32(invalid)
    np.copyto(c_plus, c, where=k_best == k - 1)
    better = c < best
    np.copyto(k_best, k, where=better)
    np.copyto(c_minus, prev, where=better)
    c_plus[better] = np.inf
    np.minimum(best, c, out=best)
    total += np.minimum(c, np.float32(truncate))
    seen_any |= seen
    return c


@njit(parallel=True, cache=True, fastmath=False)
def _finish(
    state: tuple[F32, NDArray[np.int32], F32, F32, F32, NDArray[np.bool_]],
    base: F32,
    offsets: F32,
    invalid: np.float32,
    out: tuple[F32, F32, NDArray[np.bool_], NDArray[np.bool_]],
) -> None:
    best, k_best, c_minus, c_plus, total, seen_any = state
    disp, mean, bound, no_view = out
    n = offsets.shape[0]
    per = np.float32(max(n, 1))
    half, tiny, invalid_half = np.float32(0.5), np.float32(1e-9), invalid * np.float32(0.5)
    with_base = base.shape[0] > 0
    for y in prange(best.shape[0]):
        for x in range(best.shape[1]):
            k = k_best[y, x]
            b0 = base[y, x] if with_base else np.float32(0.0)
            # each candidate as ``_pick`` makes it: the base map plus the offset (or the level alone)
            at = b0 + offsets[k] if with_base else offsets[k]
            up = b0 + offsets[min(k + 1, n - 1)] if with_base else offsets[min(k + 1, n - 1)]
            down = b0 + offsets[max(k - 1, 0)] if with_base else offsets[max(k - 1, 0)]
            step = up - down
            cm, cp, b = c_minus[y, x], c_plus[y, x], best[y, x]
            interior = np.isfinite(cm) and np.isfinite(cp) and cm < invalid and cp < invalid
            den = cm + cp - np.float32(2.0) * b
            ok = interior and den > tiny
            sub = half * (cm - cp) / den if ok else np.float32(0.0)
            sub = min(max(sub, -half), half) * (step * half if ok else np.float32(0.0))
            disp[y, x] = at + sub
            mean[y, x] = total[y, x] / per
            bound[y, x] = n > 2 and (k == 0 or k == n - 1)
            no_view[y, x] = (not seen_any[y, x]) or b >= invalid_half


def finish(
    state: tuple[F32, NDArray[np.int32], F32, F32, F32, NDArray[np.bool_]],
    base: F32 | None,
    offsets: F32,
    invalid: float,
) -> tuple[F32, F32, NDArray[np.bool_], NDArray[np.bool_]]:
    """The sweep's result from its ``state`` (see :func:`update`) in one pass: the best candidate moved by the
    parabola through its neighbours' costs (half a step at most), the mean cost, whether the best lay at the
    first or last of more than two candidates, and where no view saw the point. Candidate k is ``base +
    offsets[k]`` per pixel, or ``offsets[k]`` without a base. ``costvolume.finish_reference`` is the numpy form
    it matches bit for bit (issue 24: about ten frame-sized temporaries there)."""
    shape = state[0].shape
    out = (
        np.empty(shape, np.float32),
        np.empty(shape, np.float32),
        np.empty(shape, np.bool_),
        np.empty(shape, np.bool_),
    )
    b = np.zeros((0, 0), np.float32) if base is None else np.ascontiguousarray(base, np.float32)
    _finish(state, b, np.ascontiguousarray(offsets, np.float32), np.float32(invalid), out)
    return out
