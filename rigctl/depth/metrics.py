"""Depth error figures against ground truth, sub-pixel ones included.

``locking_pct`` measures pixel locking: estimates that crowd at integer (or 1/16) values. It is the total
variation distance, in percent, between the histogram of the fractional part of the estimates and that of the
truth at the same pixels (10 bins): 0 when the estimates' fractions are spread like the truth's, up to 100
when every estimate sits in a bin the truth never visits.
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
log = logging.getLogger(__name__)

THRESHOLDS = (0.1, 0.2, 0.5, 1.0, 2.0)
BINS = 10


def locking(estimate: NDArray[np.floating], truth: NDArray[np.floating]) -> float:
    """Pixel-locking figure (percent) of finite ``estimate`` values against ``truth`` at the same pixels."""
    if estimate.size == 0:
        return 0.0
    h_e = np.histogram(np.mod(estimate, 1.0), BINS, (0.0, 1.0))[0] / estimate.size
    h_t = np.histogram(np.mod(truth, 1.0), BINS, (0.0, 1.0))[0] / truth.size
    return float(50.0 * np.abs(h_e - h_t).sum())


def score(
    disparity: F32, truth: F32, mask: NDArray[np.bool_], scene: NDArray[np.bool_] | None = None
) -> dict[str, float | None]:
    """Metrics on ``mask`` (pixels with ground truth): bad 0.1 / 0.2 / 0.5 / 1 / 2 px (a missing estimate
    counts as bad); MAE, RMS and MSE x 100 (px^2) over the estimated pixels; the pixel-locking figure; the
    share with no estimate. And both sides of the silhouette, as a share of ``mask``'s pixel count: **false
    foreground** (an estimate where the truth has none: on a green screen, depth painted beside the subject),
    counted over ``scene`` (default every pixel), and **missed foreground** (the truth has depth, the
    estimate none)."""
    t = truth[mask]
    d = disparity[mask]
    have = np.isfinite(d)
    with np.errstate(invalid="ignore"):
        err = np.where(have, np.abs(d - t), np.inf)
    bad = {f"bad_{x}": float(np.mean(err > x) * 100) if t.size else 0.0 for x in THRESHOLDS}
    e = err[have]
    return {
        **bad,
        "mae_px": float(e.mean()) if e.size else None,  # None: nothing was estimated
        "rms_px": float(np.sqrt(np.mean(e**2))) if e.size else None,
        "mse_x100": float(np.mean(e**2) * 100) if e.size else None,
        "locking_pct": locking(d[have], t[have]) if e.size else None,
        "no_estimate_pct": float(np.mean(~have) * 100) if t.size else 0.0,
        **silhouette(disparity, truth, mask, scene),
        "pixels": int(t.size),
    }


def silhouette(
    disparity: F32, truth: F32, mask: NDArray[np.bool_], scene: NDArray[np.bool_] | None = None
) -> dict[str, float]:
    """False and missed foreground (see :func:`score`) in percent of ``mask``'s pixels, and the pixel count
    of the false foreground (0 % of an empty mask is not a figure: then the percentages are 0 and the count
    says what there is)."""
    est = np.isfinite(disparity)
    false = est & ~np.isfinite(truth)
    if scene is not None:
        false &= scene
    n = int(mask.sum())
    n_false, n_missed = int(false.sum()), int((mask & ~est).sum())
    return {
        "false_fg_pct": 100.0 * n_false / n if n else 0.0,
        "missed_fg_pct": 100.0 * n_missed / n if n else 0.0,
        "false_fg_pixels": n_false,
    }
