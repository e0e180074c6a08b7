"""A key's alpha against a true alpha, with the alpha-matting benchmark's four measures (Rhemann et al.,
"A Perceptually Motivated Online Benchmark for Image Matting", CVPR 2009), on the **edge band**: the pixels
within ``band_px`` of the true silhouette (where the true alpha is fractional, or where it steps between 0
and 1), which is where keys differ; far inside the subject or out on the screen every sensible key agrees.

* SAD: the sum of |alpha - truth| over the band, in thousands (as the benchmark reports it);
* MSE: the mean of (alpha - truth)^2 over the band;
* gradient: the sum over the band of (|grad alpha| - |grad truth|)^2, the gradients from first-order
  Gaussian derivatives (sigma 1.4), in thousands;
* connectivity: the sum over the band of |phi(alpha) - phi(truth)|, in thousands, where phi(a)_i =
  1 - d_i [d_i >= 0.15] and d_i = a_i - l_i, l_i the last threshold (in steps of 0.1) at which pixel i is
  still 4-connected to the region where both mattes are opaque: a key whose soft hair is cut off from the
  head scores worse than one whose hair is as soft but attached.
"""

from __future__ import annotations

from typing import TypedDict

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
SIGMA = 1.4
THETA = 0.15
STEP = 0.1


class MatteScores(TypedDict):
    sad_k: float
    mse: float
    gradient_k: float
    connectivity_k: float
    band_pixels: int


def edge_band(truth: F32, band_px: int = 3) -> NDArray[np.bool_]:
    """Pixels within ``band_px`` of the truth's silhouette: its fractional pixels and its 0/1 steps, grown."""
    fractional = (truth > 0) & (truth < 1)
    kernel = np.ones((3, 3), np.uint8)
    opaque, clear = (truth >= 1).astype(np.uint8), (truth <= 0).astype(np.uint8)
    step = (cv2.dilate(opaque, kernel) > 0) & (cv2.dilate(clear, kernel) > 0)
    seed = (fractional | step).astype(np.uint8)
    size = 2 * band_px + 1
    return np.asarray(cv2.dilate(seed, np.ones((size, size), np.uint8)) > 0)


def _gradient(a: F32) -> F32:
    blur = cv2.GaussianBlur(a, (0, 0), SIGMA)
    gx = cv2.Sobel(blur, cv2.CV_32F, 1, 0, ksize=1) / 2
    gy = cv2.Sobel(blur, cv2.CV_32F, 0, 1, ksize=1) / 2
    return np.asarray(np.hypot(gx, gy), np.float32)


def _phi(a: F32, source: NDArray[np.bool_], levels: NDArray[np.float64]) -> F32:
    """1 - d [d >= THETA], d = a - (the last level at which the pixel is 4-connected to ``source``)."""
    last = np.zeros(a.shape, np.float32)
    for t in levels:
        n, labels = cv2.connectedComponents((a >= t).astype(np.uint8), connectivity=4)
        keep = np.zeros(n, bool)
        keep[np.unique(labels[source & (a >= t)])] = True
        keep[0] = False
        last[keep[labels]] = np.float32(t)
    d = a - last
    return np.asarray(1.0 - d * (d >= THETA), np.float32)


def matte_scores(alpha: F32, truth: F32, band: NDArray[np.bool_] | None = None) -> MatteScores:
    """The four measures of ``alpha`` against ``truth`` (both 0..1) on ``band`` (default :func:`edge_band`)."""
    alpha = np.clip(np.asarray(alpha, np.float32), 0, 1)
    truth = np.clip(np.asarray(truth, np.float32), 0, 1)
    where = edge_band(truth) if band is None else band
    n = int(where.sum())
    if n == 0:
        return {"sad_k": 0.0, "mse": 0.0, "gradient_k": 0.0, "connectivity_k": 0.0, "band_pixels": 0}
    diff = (alpha - truth)[where].astype(np.float64)
    grad = ((_gradient(alpha) - _gradient(truth))[where].astype(np.float64)) ** 2
    source = (alpha >= 1) & (truth >= 1)
    if source.any():  # the largest opaque region both agree on
        _n, labels, stats, _ = cv2.connectedComponentsWithStats(source.astype(np.uint8), connectivity=4)
        source = labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    levels = np.arange(STEP, 1.0 + 1e-9, STEP)
    conn = np.abs(_phi(alpha, source, levels) - _phi(truth, source, levels))[where].astype(np.float64)
    return {
        "sad_k": float(np.abs(diff).sum() / 1000),
        "mse": float(np.mean(diff**2)),
        "gradient_k": float(grad.sum() / 1000),
        "connectivity_k": float(conn.sum() / 1000),
        "band_pixels": n,
    }
