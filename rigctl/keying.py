"""Green-screen keying: a matte of the subject (1) against the screen (0), with spill suppression, so that
depth is never computed for the screen and the screen never "matches" at a silhouette.

A colour-difference keyer: screen-ness s = g - max(r, b), relative to the screen's own s measured from the
image (its dominant green); the matte falls from 1 to 0 between ``low`` and ``high`` fractions of it. Spill
(green light bounced onto the subject) is removed by clamping g to max(r, b) where the matte is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@dataclass(frozen=True)
class Keyer:
    low: float = 0.25  # below this fraction of the screen's green excess: subject
    high: float = 0.55  # above: screen
    min_area: float = 0.0005  # subject blobs smaller than this share of the image are screen noise
    # what makes green a screen and not foliage or a green prop in a scene without one: a saturated green
    # (screens sit near 0.3 of full scale in g - max(r, b)), smooth (its fine detail, the median deviation
    # from a 7x7 blur, is sensor noise, a few % of its level; leaves and textured props are far above:
    # uneven light varies slowly and does not count), covering a share of the view and reaching its edge
    min_excess: float = 0.12
    max_texture: float = 0.05
    min_screen_share: float = 0.05

    def screen_excess(self, rgb: F32) -> float:
        """The screen's typical green excess: the 90th percentile of g - max(r, b) over clearly green pixels;
        0 when no green screen is in view (then nothing is keyed: a scene without a screen needs no key)."""
        s = rgb[..., 1] - np.maximum(rgb[..., 0], rgb[..., 2])
        green = s[s > 0.05]
        if green.size <= 0.01 * s.size:
            return 0.0
        excess = float(np.percentile(green, 90))
        if excess < self.min_excess:
            return 0.0
        screen = s > 0.5 * excess
        _n, labels = cv2.connectedComponents(screen.astype(np.uint8), connectivity=8)
        edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
        edge = edge[edge > 0]
        at_edge = np.isin(labels, edge) if edge.size else np.zeros_like(screen)
        if at_edge.mean() < self.min_screen_share:
            return 0.0
        detail = np.abs(s - cv2.GaussianBlur(s, (7, 7), 0))[at_edge]
        if float(np.median(detail)) > self.max_texture * float(np.median(s[at_edge])):
            return 0.0
        return excess

    def matte(self, rgb: F32) -> F32:
        """Subject opacity in [0, 1]; all ones when there is no screen in view."""
        excess = self.screen_excess(rgb)
        if excess <= 0:
            return np.ones(rgb.shape[:2], np.float32)
        s = (rgb[..., 1] - np.maximum(rgb[..., 0], rgb[..., 2])) / excess
        a = np.clip((self.high - s) / (self.high - self.low), 0.0, 1.0).astype(np.float32)
        solid = (a > 0.5).astype(np.uint8)
        _n, labels, stats, _ = cv2.connectedComponentsWithStats(solid, connectivity=8)
        small = stats[:, cv2.CC_STAT_AREA] < self.min_area * a.size
        small[0] = False
        if small.any():
            a[small[labels]] = 0.0
        return a

    @staticmethod
    def despill(rgb: F32, matte: F32) -> F32:
        limit = np.maximum(rgb[..., 0], rgb[..., 2])
        out = rgb.copy()
        out[..., 1] = np.where(matte > 0, np.minimum(rgb[..., 1], limit), rgb[..., 1])
        return out


def subject_box(mask: NDArray[np.bool_], margin: int) -> tuple[int, int, int, int] | None:
    """(y0, y1, x0, x1) of the mask's bounding box widened by ``margin``; None when the mask is empty."""
    ys = np.flatnonzero(mask.any(1))
    xs = np.flatnonzero(mask.any(0))
    if not len(ys):
        return None
    h, w = mask.shape
    return max(0, ys[0] - margin), min(h, ys[-1] + 1 + margin), max(0, xs[0] - margin), min(w, xs[-1] + 1 + margin)
