"""The disparity range of an input that comes with no plan, measured from the images themselves.

Without --near/--far or a grid's ``disparity_range_px``, the search would span every plausible disparity
(0 to a quarter of the width), which misses the negative disparities of a light field focused inside the
scene and costs several times the work. Instead, SIFT features of the centre camera are matched with every
other camera; each match that obeys the grid geometry (a point at (x, y) appears at (x, y) - d * offset)
votes for a disparity d. A feature counts when at least three cameras agree on its d (a chance match on
the epipolar line does not survive that), and the range spans every such feature, widened by a margin: thin
structures in front are few features, so no percentile may cut them off.

In front of a green screen nothing is at infinity: a feature at zero disparity in every camera is fixed to
the sensor (a burnt-in id or timecode, dust on a window), not in the scene, and does not count
(``screen=True``; a light field's background at infinity is a legitimate zero).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import cv2
import numpy as np

from rigctl.depth.grid import Grid

log = logging.getLogger(__name__)

MIN_FEATURES = 20  # fewer agreed features than this: the images do not say, keep the plausible range
MAX_RESIDUAL_PX = 1.0  # off the line a match of a rectified grid must lie on
AGREE_PX = 0.5  # cameras agree on a feature's disparity within this
MIN_CAMERAS = 3  # (two where the grid has only two other cameras)


def _gray(grid: Grid, name: str) -> np.ndarray:
    return cv2.cvtColor(grid.bgr8(name), cv2.COLOR_BGR2GRAY)


def disparity_votes(grid: Grid, max_features: int = 4000) -> np.ndarray:
    """Disparities (for one horizontal spacing) of the centre camera's SIFT features that several cameras
    agree on, one per feature."""
    if len(grid.names) < 2:
        return np.zeros(0)
    centre = np.mean([grid.offsets[n] for n in grid.names], axis=0)
    ref = min(grid.names, key=lambda n: float(np.hypot(*(np.asarray(grid.offsets[n]) - centre))))
    sift = cv2.SIFT.create(nfeatures=max_features)
    kp_ref, des_ref = sift.detectAndCompute(_gray(grid, ref), None)
    if des_ref is None or len(kp_ref) < 2:
        return np.zeros(0)
    p_ref = np.array([k.pt for k in kp_ref], np.float64)
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    votes: dict[int, list[float]] = {}
    others = 0
    for name in grid.names:
        if name == ref:
            continue
        ox = grid.offsets[name][0] - grid.offsets[ref][0]
        oy = grid.offsets[name][1] - grid.offsets[ref][1]
        norm = ox * ox + oy * oy
        if norm == 0:
            continue
        kp, des = sift.detectAndCompute(_gray(grid, name), None)
        others += 1
        if des is None or len(kp) < 2:
            continue
        p = np.array([k.pt for k in kp], np.float64)
        pairs = [m for m, n in (mm for mm in matcher.knnMatch(des_ref, des, k=2) if len(mm) == 2)
                 if m.distance < 0.75 * n.distance]  # fmt: skip
        if not pairs:
            continue
        a = p_ref[[m.queryIdx for m in pairs]]
        b = p[[m.trainIdx for m in pairs]]
        delta = b - a  # = -d * (ox, oy)
        d = -(delta[:, 0] * ox + delta[:, 1] * oy) / norm
        residual = np.hypot(delta[:, 0] + d * ox, delta[:, 1] + d * oy)
        for m, dm, ok in zip(pairs, d, residual < MAX_RESIDUAL_PX, strict=True):
            if ok:
                votes.setdefault(m.queryIdx, []).append(float(dm))
    need = min(MIN_CAMERAS, max(2, others))
    agreed = []
    for ds in votes.values():
        if len(ds) < need:
            continue
        med = float(np.median(ds))
        if sum(abs(x - med) <= AGREE_PX for x in ds) >= need:
            agreed.append(med)
    return np.asarray(agreed, np.float64)


def measured_range(grids: Grid | Sequence[Grid], screen: bool = False) -> tuple[float, float] | None:
    """The range the images show (the features of every grid given, pooled: a take's sample of frame sets),
    or None when too few matches agree to say. ``screen``: the views show a green screen, so features at
    zero disparity are fixed to the sensor and left out (see the module)."""
    sample = [grids] if isinstance(grids, Grid) else list(grids)
    votes = np.concatenate([disparity_votes(g) for g in sample]) if sample else np.zeros(0)
    votes = votes[np.isfinite(votes)]
    if screen:
        fixed = np.abs(votes) <= AGREE_PX
        if fixed.any():
            log.info("%d features at zero disparity in front of a green screen: fixed to the sensor", fixed.sum())
        votes = votes[~fixed]
    if votes.size < MIN_FEATURES:
        log.info("no plan and only %d features the cameras agree on: searching the whole plausible range", votes.size)
        return None
    lo, hi = float(votes.min()), float(votes.max())
    margin = max(3.0, 0.3 * (hi - lo))  # features are sparse: the nearest and farthest points may have none
    return float(lo - margin), float(hi + margin)
