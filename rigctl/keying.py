"""Green-screen keying: a matte of the subject (1) against the screen (0), with spill suppression, so that
depth is never computed for the screen and the screen never "matches" at a silhouette.

A colour-difference keyer: screen-ness s = g - max(r, b), relative to the screen's own s measured from the
image (its dominant green); the matte falls from 1 to 0 between ``low`` and ``high`` fractions of it. Spill
(green light bounced onto the subject) is removed by clamping g to max(r, b) where the matte is kept.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.local_mean import LocalMean

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

    def soft(
        self,
        rgb: F32 | None,
        hard: F32 | None = None,
        everywhere: bool = False,
        again: Callable[[], F32] | None = None,
    ) -> SoftKey:
        """The subject's coverage of every pixel (alpha, fractional on the edge) and its colour unmixed from
        the screen behind it (:func:`soft_key`); all ones and the picture itself without a screen. ``hard``:
        this keyer's :meth:`matte` of the same picture when it was already computed (depth keys each camera);
        ``everywhere``: the reference solved on every pixel, not only the edge band; ``again``: see
        :func:`soft_key`."""
        return soft_key(rgb, self, hard, everywhere, again)

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
SPECK = 0.8  # a green excess below this share of the screen's may be a speck of the subject (10x its noise)
SMALL_ALPHA = 0.1  # below this the unmixed colour leans on the nearby subject's (dividing by alpha is noise)
BAND_PX = 16  # at 1920 px wide: how far past the subject (the hard key's, and partial cover) the key looks
STEP_PX = 2  # and past its faintest cover (a speck of screen noise is not followed further than this)


@dataclass(frozen=True)
class SoftKey:
    alpha: F32  # H x W, the share of each pixel the subject covers
    foreground: F32  # H x W x 3, the subject's own colour (unmixed from the screen, spill suppressed)
    solved: int = 0  # how many pixels the key was solved on (the edge band); the rest are 0 or 1


@dataclass
class _Pass:
    """One pass of the key at the solved pixels (all N long): alpha, the pairs' alpha, and what unmixing
    needs (the screen's colour and chroma direction, the nearby subject's colour and whether there was one)."""

    alpha: F32
    pair_alpha: F32
    back: F32
    u: F32
    front: F32
    have_front: F32


def _solve(ycc: F32, idx: NDArray[np.intp], front_mean: LocalMean, back_mean: LocalMean, pairs: bool) -> _Pass:
    """The key's alpha at ``idx`` (every 4:2:2 pair whole, in frame order) for one estimate of the screen;
    ``ycc``: the picture's Y, Cb, Cr (and anything after them) per pixel, N x 3 or more."""
    pix = ycc[idx, :3]
    front, have_front = front_mean.at(idx)
    back, _ = back_mean.at(idx)
    chroma_b = back[:, 1:]
    level = np.maximum(np.linalg.norm(chroma_b, axis=1), 1e-3)
    u = chroma_b / level[:, None]  # the screen's chroma direction
    e_i = np.einsum("nc,nc->n", pix[:, 1:], u)
    e_f = np.where(have_front > 0, np.einsum("nc,nc->n", front[:, 1:], u), 0.0)
    e_f = np.minimum(e_f, 0.5 * level)
    pair_alpha = np.clip((level - e_i) / (level - e_f), 0.0, 1.0).astype(np.float32)
    # the solved pixels in frame order hold every pair whole, so a pair is two neighbours here too
    alpha = _split_pairs(pair_alpha, pix[:, 0], back[:, 0]) if pairs else pair_alpha
    alpha = np.where(alpha < SURE, 0.0, np.where(alpha > 1 - SURE, 1.0, alpha)).astype(np.float32)
    return _Pass(alpha, pair_alpha if pairs else alpha, back, u, front, have_front)


def _near(mask: NDArray[np.bool_], r: int, pairs: bool) -> NDArray[np.bool_]:
    """Pixels within ``r`` of ``mask`` (along both axes: a square, the fast dilation), with both pixels of
    every 4:2:2 pair."""
    near = cv2.dilate(mask.astype(np.uint8), np.ones((2 * r + 1, 2 * r + 1), np.uint8)) > 0 if r else mask.copy()
    if pairs:
        both = near[:, 0::2] | near[:, 1::2]
        near[:, 0::2], near[:, 1::2] = both, both
    return np.asarray(near)


def _cover(rgb: F32, hard: F32) -> NDArray[np.bool_]:
    """Where the subject may be: the hard key's subject, and every pixel whose green excess is clearly below the
    screen's (its median over the hard key's screen): the specks the hard key drops as noise, which include
    strands cut off from the subject (by the frame's edge, or flying free)."""
    s = rgb[..., 1] - np.maximum(rgb[..., 0], rgb[..., 2])
    sample = s[::4, ::4][hard[::4, ::4] <= 0]
    level = float(np.median(sample)) if sample.size else 0.0
    return np.asarray((hard > 0) | (s < SPECK * level)) if level > 0 else np.asarray(hard > 0)


def soft_key(
    rgb: F32 | None,
    keyer: Keyer,
    hard: F32 | None = None,
    everywhere: bool = False,
    again: Callable[[], F32] | None = None,
) -> SoftKey:
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

    The key is solved on the subject's edge band only (a few % of a presenter's frame): the pixels within
    :data:`BAND_PX` (scaled with the width) of the hard key's subject or of a speck less green than the
    screen (:func:`_cover`), grown by as much around every pixel the key finds more than :data:`SMALL_ALPHA`
    of it in, and by :data:`STEP_PX` around any it finds some in (strands the hard key missed, followed out
    to their tips). Well inside the subject the key is 1 and the colour as captured; on the screen beyond the band 0
    (and the colour as captured, which alpha hides): a speck of screen noise away from the subject is screen.
    ``everywhere``: solve every pixel (the reference the band is tested against).

    ``hard``: ``keyer.matte`` of the picture, when the caller has it (depth keys each camera): used when the
    picture lies within [0, 1] (where clipping it, as the key does first, changes nothing) and has its shape,
    else made again. It is below 1 somewhere exactly when the keyer found a screen (the screen's own pixels
    key to 0), so it also says whether there is one.

    ``again``: makes the picture anew, a new array each call. With ``rgb`` None the key makes it so, holds it
    only until it has its Y, Cb, Cr and makes it again for the colour, instead of holding the picture and a
    copy of it through the solve (issue 24: 0.1 GiB at 4K, at the write's peak); nothing above holds it."""
    if rgb is None:
        if again is None:
            raise ValueError("soft_key: no picture and no way to make one")
        rgb = again()
    captured = np.asarray(rgb, np.float32)
    del rgb
    # NaN fails both tests: clipped, as before; an empty picture has nothing to clip
    least, most = (float(captured.min()), float(captured.max())) if captured.size else (0.0, 0.0)
    within = least >= 0.0 and most <= 1.0
    rgb = captured if within else np.clip(captured, 0.0, 1.0)  # no copy when within
    if hard is None or not within or hard.shape != rgb.shape[:2]:
        hard = keyer.matte(rgb)
    if not bool((hard < 1).any()):
        return SoftKey(np.ones(rgb.shape[:2], np.float32), captured if again is not None else captured.copy())
    cover = _cover(rgb, hard)
    ycc1 = ycc_with_ones(rgb)
    del rgb  # the clipped copy, when one was made
    if again is not None:
        del captured  # made again for the colour
    full, idx, done, solved = _key_band(ycc1, cover, hard, everywhere)
    del ycc1
    lo, hi = min(0.0, least), max(1.0, most)
    fg = captured.copy() if again is None else np.asarray(again(), np.float32)
    at = fg.reshape(-1, fg.shape[2])
    at[idx] = _unmix(solved, done, at[idx], (lo, hi))
    return SoftKey(full, fg, len(idx))


YCC_BAND_ROWS = 64  # rows of the picture turned into Y, Cb, Cr at a time by :func:`ycc_with_ones`


def ycc_with_ones(rgb: F32) -> F32:
    """The picture's Y, Cb, Cr and a channel of ones (:func:`rigctl.local_mean.with_ones`, what the local means
    weigh), made YCC_BAND_ROWS rows at a time: numpy multiplies a stack of rows by the matrix one row at a time,
    so the bits are the whole picture's, without a frame of Y, Cb, Cr beside them (issue 24: 0.1 GiB at 4K, at
    the write's peak)."""
    h, w = rgb.shape[:2]
    out = np.empty((h, w, 4), np.float32)
    for y0 in range(0, h, YCC_BAND_ROWS):
        out[y0 : y0 + YCC_BAND_ROWS, :, :3] = rgb[y0 : y0 + YCC_BAND_ROWS] @ RGB_TO_YCC.T
    out[..., 3] = 1.0
    return out


def _key_band(
    ycc1: F32, cover: NDArray[np.bool_], hard: F32, everywhere: bool
) -> tuple[F32, NDArray[np.intp], _Pass, F32]:
    """:func:`soft_key`'s alpha over the frame from the picture's Y, Cb, Cr and ones (``ycc1``,
    :func:`ycc_with_ones`) and where the subject may be (``cover``, :func:`_cover`), the pixels it was solved on,
    the last pass there and their Y, Cb, Cr; every frame-sized temporary (the local means' fields) is gone
    when it returns, before the colour is unmixed into a copy of the picture (issue 24: the write's memory)."""
    # 4:2:2 decoded: the two pixels of each pair share their chroma (but where decoding clipped)
    h, w = hard.shape
    chroma = ycc1[..., 1:3]
    pairs = w % 2 == 0 and float(np.mean(np.abs(chroma[:, 0::2] - chroma[:, 1::2]) < 2e-3)) > 0.95
    k3 = np.ones((3, 3), np.uint8)
    # the means' weights, 0 or 1 in bytes (a byte times a float32 is that float32's product: issue 24, the
    # write's peak, 25 MB each at 4K)
    solid = np.asarray(cv2.erode((hard >= 1).astype(np.uint8), k3), np.uint8)
    screen = np.asarray(cv2.erode((hard <= 0).astype(np.uint8), k3), np.uint8)
    inner = (cv2.erode(solid, k3) > 0).reshape(-1)  # well inside the hard key: the subject
    pix_ycc = ycc1.reshape(-1, 4)
    r = max(4, round(BAND_PX * w / 1920))
    outside = _near(~inner.reshape(h, w), 0, pairs)  # and both pixels of a pair one of which is outside
    band = np.ones((h, w), bool) if everywhere else _near(cover, r, pairs) & outside
    idx = np.flatnonzero(band)
    # the nearby subject (the same in both passes) and the screen: their fine blurs on the band, the key's
    # dearest step, side by side (OpenCV lets go of the GIL; both are held at once either way, within a few MB)
    with ThreadPoolExecutor(1, thread_name_prefix="soft-key-front") as beside:
        made = beside.submit(lambda: LocalMean(ycc1, solid, (3.0, 12.0)).made(0, idx))
        back = LocalMean(ycc1, screen, (4.0, 16.0, 64.0)).made(0, idx)
        front = made.result()
    full = inner.astype(np.float32)  # the key over the frame: 1 inside, 0 on the screen

    def solve(idx: NDArray[np.intp], back: LocalMean) -> _Pass:
        done = _solve(pix_ycc, idx, front, back, pairs)
        done.alpha[inner[idx]] = 1.0  # solved as part of a pair, but inside the subject
        full[idx] = done.alpha
        return done

    solve(idx, back)
    while not everywhere:  # the first pass follows strands out past the band
        found = full.reshape(h, w)
        more = _near((found > SMALL_ALPHA) & band, r, pairs) | _near((found > 0) & band, STEP_PX, pairs)
        more &= ~band & outside
        if not more.any():
            break
        band |= more
        solve(np.flatnonzero(more), back)
    idx = np.flatnonzero(band)
    # the second pass measures the screen without the faint strands the first one found
    del back  # its fields (the second pass's take their place)
    screen = np.asarray(cv2.erode((full.reshape(h, w) <= 0).astype(np.uint8), k3), np.uint8)
    done = solve(idx, LocalMean(ycc1, screen, (4.0, 16.0, 64.0)))
    solved = pix_ycc[idx, :3]
    return full.reshape(h, w), idx, done, solved


def _split_pairs(pair_alpha: F32, luma: F32, screen_luma: F32) -> F32:
    """Per-pixel alpha from a pair's mean alpha and each pixel's luma (pairs along the last axis): with the
    pair's mix Ybar = abar Y_F + (1 - abar) Y_B, a1 - a2 = abar (Y1 - Y2) / (Ybar - Y_B); where Ybar is too
    close to the screen's luma to tell, both keep the pair's."""
    y1, y2 = luma[..., 0::2], luma[..., 1::2]
    abar = pair_alpha[..., 0::2]
    lever = 0.5 * (y1 + y2) - 0.5 * (screen_luma[..., 0::2] + screen_luma[..., 1::2])
    usable = np.abs(lever) >= MIN_LUMA_LEVER
    half = np.where(usable, abar * (y1 - y2) / np.where(usable, 2 * lever, 1.0), 0.0)
    # within [0, 1] with the pair's sum kept where it can be
    half = np.clip(half, np.maximum(abar - 1, -abar), np.minimum(1 - abar, abar))
    out = np.empty_like(pair_alpha)
    out[..., 0::2], out[..., 1::2] = abar + half, abar - half
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def _unmix(ycc: F32, key: _Pass, captured: F32, limits: tuple[float, float]) -> F32:
    """F = B + (I - B) / a, luma per pixel and chroma with the alpha it was mixed with; toward the nearby
    subject's colour as alpha goes to 0; spill held to the nearby subject's along the screen's chroma. Within
    ``limits`` (the captured picture's range, at least [0, 1]); ``captured`` itself where the subject is whole.
    Every array is per solved pixel (N x 3, N)."""
    back, front, u, alpha = key.back, key.front, key.u, key.alpha
    y = back[:, 0] + (ycc[:, 0] - back[:, 0]) / np.maximum(alpha, 1e-3)
    c = back[:, 1:] + (ycc[:, 1:] - back[:, 1:]) / np.maximum(key.pair_alpha, 1e-3)[:, None]
    unmixed = np.concatenate([y[:, None], c], axis=1)
    near = np.where(key.have_front[:, None] > 0, front, unmixed)
    t = np.clip(np.minimum(alpha, key.pair_alpha) / SMALL_ALPHA, 0.0, 1.0)[:, None]
    f = t * unmixed + (1 - t) * near
    e_near = np.maximum(np.einsum("nc,nc->n", near[:, 1:], u), 0.0)
    excess = np.maximum(np.einsum("nc,nc->n", f[:, 1:], u) - e_near, 0.0)
    f[:, 1:] -= excess[:, None] * u
    rgb = np.clip(f @ YCC_TO_RGB.T, *limits).astype(np.float32)
    solid = alpha >= 1
    rgb[solid] = captured[solid]  # the subject as captured where it is whole, super-whites included
    return rgb
