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

    def soft(self, rgb: F32, hard: F32 | None = None) -> SoftKey:
        """The subject's coverage of every pixel (alpha, fractional on the edge) and its colour unmixed from
        the screen behind it (:func:`soft_key`); all ones and the picture itself without a screen. ``hard``:
        this keyer's :meth:`matte` of the same picture when it was already computed (depth keys each camera)."""
        return soft_key(rgb, self, hard)

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


# ---- the soft key ---------------------------------------------------------------------------------------

RGB_TO_YCC = np.array(
    [[0.2126, 0.7152, 0.0722], [-0.1146, -0.3854, 0.5], [0.5, -0.4542, -0.0458]], np.float32
)  # BT.709: Y, Cb, Cr
YCC_TO_RGB = np.linalg.inv(RGB_TO_YCC).astype(np.float32)
SURE = 0.02  # alpha within this of 0 or 1 is 0 or 1 (sensor noise on the screen and on the subject)
MIN_LUMA_LEVER = 0.02  # below this luma between a pair and the screen, both pixels of the pair share alpha
SMALL_ALPHA = 0.1  # below this the unmixed colour leans on the nearby subject's (dividing by alpha is noise)


@dataclass(frozen=True)
class SoftKey:
    alpha: F32  # H x W, the share of each pixel the subject covers
    foreground: F32  # H x W x 3, the subject's own colour (unmixed from the screen, spill suppressed)


def _local_mean(values: F32, weight: F32, sigmas: tuple[float, ...]) -> tuple[F32, F32]:
    """Normalised convolution: the weighted local mean of ``values`` (H x W x C) at the first of ``sigmas``
    that has weight nearby, else the next; and where none had any (a 0/1 map)."""
    out = np.zeros(values.shape, np.float32)
    done = np.zeros(weight.shape, bool)
    h, w = weight.shape
    c = values.shape[2]
    # the weighted values and the weight side by side, built once for every sigma
    weighted = np.empty((h, w, c + 1), np.float32)
    np.multiply(values, weight[..., None], out=weighted[..., :c])
    weighted[..., c] = weight
    for sigma in sigmas:
        scale = max(1, int(sigma // 4))  # a wide blur at a coarser scale: the same field, a fraction of the time
        if scale > 1:
            small = cv2.resize(weighted, (max(1, w // scale), max(1, h // scale)), interpolation=cv2.INTER_AREA)
            both = cv2.resize(cv2.GaussianBlur(small, (0, 0), sigma / scale), (w, h), interpolation=cv2.INTER_LINEAR)
        else:
            both = cv2.GaussianBlur(weighted, (0, 0), sigma)
        num, den = both[..., :-1], both[..., -1]
        take = ~done & (den > 0.02)
        np.divide(num, den[..., None], out=out, where=take[..., None])  # in place: no gathered copies
        done |= take
    return out, done.astype(np.float32)


def soft_key(rgb: F32, keyer: Keyer, hard: F32 | None = None) -> SoftKey:
    """Alpha and the unmixed subject colour on a green screen.

    The screen's colour is estimated at every pixel from the screen around it (a smooth field: uneven light is
    measured, not assumed away), and so is the nearby subject's. A pixel is a mix I = a F + (1 - a) B: along
    the screen's chroma direction the mix gives ``a`` (the colour-difference key, with the local subject's own
    green measured rather than taken as zero). The chroma of a 4:2:2 picture (SDI, the simulator) is shared by
    two pixels, so it gives the pair's mean alpha; the luma, per pixel, splits it between them where it differs
    from the screen's enough to tell. The subject colour is then unmixed, F = B + (I - B) / a (chroma per pair,
    luma per pixel), leaning on the nearby subject's colour where ``a`` is small, and its spill suppressed: its
    component along the screen's chroma is held to the nearby subject's (the screen's light bounced onto the
    subject, or what is left of the screen in an under-estimated alpha, is not the subject's colour).

    Alpha is measured on the nominal range [0, 1]; the colour keeps what was captured beyond it (a 4:2:2
    camera's super-whites and sub-blacks): the whole subject as it is, unmixed edge colours within the
    picture's own range.

    ``hard``: ``keyer.matte`` of the picture clipped to [0, 1], when the caller has it (then it is not computed
    again). It is below 1 somewhere exactly when the keyer found a screen (the screen's own pixels key to 0),
    so it also says whether there is one."""
    captured = np.asarray(rgb, np.float32)
    rgb = np.clip(captured, 0.0, 1.0)
    if hard is None:
        hard = keyer.matte(rgb)
    if not bool((hard < 1).any()):
        return SoftKey(np.ones(rgb.shape[:2], np.float32), captured.copy())
    ycc = np.asarray(rgb @ RGB_TO_YCC.T, np.float32)
    # 4:2:2 decoded: the two pixels of each pair share their chroma (but where decoding clipped)
    w = hard.shape[1]
    pairs = w % 2 == 0 and float(np.mean(np.abs(ycc[:, 0::2, 1:] - ycc[:, 1::2, 1:]) < 2e-3)) > 0.95
    k3 = np.ones((3, 3), np.uint8)
    solid = cv2.erode((hard >= 1).astype(np.uint8), k3).astype(np.float32)
    screen = cv2.erode((hard <= 0).astype(np.uint8), k3).astype(np.float32)
    alpha = hard
    front, have_front = _local_mean(ycc, solid, (3.0, 12.0))  # the nearby subject: the same in both passes
    for _ in range(2):  # the second pass measures the screen without the faint strands the first one found
        back, _ = _local_mean(ycc, screen, (4.0, 16.0, 64.0))
        chroma_b = back[..., 1:]
        level = np.maximum(np.linalg.norm(chroma_b, axis=2), 1e-3)
        u = chroma_b / level[..., None]  # the screen's chroma direction
        e_i = np.einsum("hwc,hwc->hw", ycc[..., 1:], u)
        e_f = np.where(have_front > 0, np.einsum("hwc,hwc->hw", front[..., 1:], u), 0.0)
        e_f = np.minimum(e_f, 0.5 * level)
        pair_alpha = np.clip((level - e_i) / (level - e_f), 0.0, 1.0).astype(np.float32)
        alpha = _split_pairs(pair_alpha, ycc[..., 0], back[..., 0]) if pairs else pair_alpha
        alpha = np.where(alpha < SURE, 0.0, np.where(alpha > 1 - SURE, 1.0, alpha)).astype(np.float32)
        alpha[cv2.erode(solid.astype(np.uint8), k3) > 0] = 1.0  # well inside the hard key: the subject
        screen = cv2.erode((alpha <= 0).astype(np.uint8), k3).astype(np.float32)
    fg = _unmix(ycc, back, front, have_front, alpha, pair_alpha if pairs else alpha, u, captured)
    return SoftKey(alpha, fg)


def _split_pairs(pair_alpha: F32, luma: F32, screen_luma: F32) -> F32:
    """Per-pixel alpha from a pair's mean alpha and each pixel's luma: with the pair's mix Ybar = abar Y_F +
    (1 - abar) Y_B, a1 - a2 = abar (Y1 - Y2) / (Ybar - Y_B); where Ybar is too close to the screen's luma to
    tell, both keep the pair's."""
    y1, y2 = luma[:, 0::2], luma[:, 1::2]
    abar = pair_alpha[:, 0::2]
    lever = 0.5 * (y1 + y2) - 0.5 * (screen_luma[:, 0::2] + screen_luma[:, 1::2])
    usable = np.abs(lever) >= MIN_LUMA_LEVER
    half = np.where(usable, abar * (y1 - y2) / np.where(usable, 2 * lever, 1.0), 0.0)
    # within [0, 1] with the pair's sum kept where it can be
    half = np.clip(half, np.maximum(abar - 1, -abar), np.minimum(1 - abar, abar))
    out = np.empty_like(pair_alpha)
    out[:, 0::2], out[:, 1::2] = abar + half, abar - half
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _unmix(
    ycc: F32, back: F32, front: F32, have_front: F32, alpha: F32, chroma_alpha: F32, u: F32, captured: F32
) -> F32:
    """F = B + (I - B) / a, luma per pixel and chroma with the alpha it was mixed with; toward the nearby
    subject's colour as alpha goes to 0; spill held to the nearby subject's along the screen's chroma. Within
    the captured picture's range (at least [0, 1]); ``captured`` itself where the subject is whole."""
    y = back[..., 0] + (ycc[..., 0] - back[..., 0]) / np.maximum(alpha, 1e-3)
    c = back[..., 1:] + (ycc[..., 1:] - back[..., 1:]) / np.maximum(chroma_alpha, 1e-3)[..., None]
    unmixed = np.concatenate([y[..., None], c], axis=2)
    near = np.where(have_front[..., None] > 0, front, unmixed)
    t = np.clip(np.minimum(alpha, chroma_alpha) / SMALL_ALPHA, 0.0, 1.0)[..., None]
    f = t * unmixed + (1 - t) * near
    e_near = np.maximum(np.einsum("hwc,hwc->hw", near[..., 1:], u), 0.0)
    excess = np.maximum(np.einsum("hwc,hwc->hw", f[..., 1:], u) - e_near, 0.0)
    f[..., 1:] -= excess[..., None] * u
    lo, hi = min(0.0, float(captured.min())), max(1.0, float(captured.max()))
    rgb = np.clip(f @ YCC_TO_RGB.T, lo, hi).astype(np.float32)
    solid = alpha >= 1
    rgb[solid] = captured[solid]  # the subject as captured where it is whole, super-whites included
    return rgb
