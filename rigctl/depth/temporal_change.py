"""Which pixels of a view changed between two consecutive frame sets by more than the sensor noise.

The colour of a still surface changes between frames only by noise, so the test needs the noise level, and it
is measured from the data, not assumed: per camera, the frame difference of every pixel (after a gain and
offset per channel, so a change of exposure or light is not taken for motion) is squared and averaged over a
small window. On the flat pixels of the picture (a small spatial gradient in both frames, nothing clipped) a
moving subject changes the colour only at its edges, so there the statistic is the noise even when most of
the picture moves (a presenter filling the frame): its median is the noise's level and its median absolute
deviation its spread, and the gain and offset are fitted there too. A pixel changed when its statistic lies
``sigmas`` spreads above that level. Each frame pair gives one level and spread per camera; the threshold
uses the median of the pairs seen so far.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import Grid

F32 = NDArray[np.float32]
MAD_TO_SIGMA = 1.4826  # the median absolute deviation of a normal distribution is 0.6745 sigma
SUBSAMPLE = 2  # every other row and column (of the half-size picture) for the fits and the noise figures
FLAT_SHARE = 0.1  # the noise is measured on this share of the pixels, the flattest ...
MIN_FLAT = 500  # ... unless fewer than this many (a small picture): then on every pixel
MIN_SPREAD = 0.05  # brightness spread (0..1) below which only an offset is fitted between frames, not a gain


@dataclass
class NoiseHistory:
    """One camera's noise figures, one per frame pair seen (level and spread of the change statistic, in 8-bit
    grey levels squared)."""

    levels: list[float] = field(default_factory=list)
    spreads: list[float] = field(default_factory=list)

    def add(self, level: float, spread: float) -> None:
        self.levels.append(level)
        self.spreads.append(spread)

    def threshold(self, sigmas: float) -> float:
        return float(np.median(self.levels) + sigmas * MAD_TO_SIGMA * np.median(self.spreads))

    def sigma(self) -> float:
        """The noise of the half-size picture (8-bit levels, one frame): the statistic's level is twice its
        variance."""
        return float(np.sqrt(max(0.0, float(np.median(self.levels))) / 2.0))


def gain_matched(prev: F32, cur: F32, flat: NDArray[np.bool_]) -> F32:
    """``prev`` with one gain and offset per channel fitted to ``cur`` on the ``flat`` pixels (where a moving
    subject hardly changes the colour, so a change of exposure is all there is to fit; every pixel when there
    are too few), least squares, then again on the pixels the first fit explains."""
    if flat.sum() >= MIN_FLAT:
        xs, ys = prev[flat], cur[flat]
    else:
        s = (slice(None, None, SUBSAMPLE), slice(None, None, SUBSAMPLE))
        xs, ys = prev[s].reshape(-1, prev.shape[2]), cur[s].reshape(-1, cur.shape[2])
    gain = np.ones(prev.shape[2], np.float32)
    offset = np.zeros(prev.shape[2], np.float32)
    for c in range(prev.shape[2]):
        x, y = xs[:, c], ys[:, c]
        keep = np.ones(x.size, bool)
        for _ in range(2):
            a, b = line_fit(x[keep], y[keep])
            r = np.abs(y - (a * x + b))
            keep = r <= 3.0 * MAD_TO_SIGMA * max(float(np.median(r)), 1e-6)
        gain[c], offset[c] = a, b
    return np.asarray(prev * gain + offset, np.float32)


def line_fit(x: F32, y: F32) -> tuple[float, float]:
    """Least-squares y = a x + b; a pure offset when x spans too little to tell a gain from noise (a flat
    screen of one colour) or there is next to nothing to fit."""
    if x.size < 16:
        return 1.0, 0.0
    mx, my = float(x.mean()), float(y.mean())
    vx = float(np.dot(x - mx, x - mx))
    if vx < MIN_SPREAD**2 * x.size:
        return 1.0, my - mx
    a = float(np.dot(x - mx, y - my)) / vx
    return a, my - a * mx


def change_statistic(prev: F32, cur: F32, window: int, flat: NDArray[np.bool_]) -> F32:
    """Mean over the window and the channels of the squared frame difference, in 8-bit levels squared."""
    diff = (cur - gain_matched(prev, cur, flat)) * np.float32(255.0)
    sq = np.asarray((diff * diff).mean(axis=2), np.float32)
    return np.asarray(cv2.boxFilter(sq, -1, (window, window), borderType=cv2.BORDER_REFLECT), np.float32)


def flat_pixels(prev: F32, cur: F32, window: int) -> NDArray[np.bool_]:
    """The flattest pixels of the picture (a spatial gradient over a window, in either frame, within 1.5 times
    the FLAT_SHARE quantile's), leaving out the clipped ones (no noise there). There a moving subject changes
    the colour only at its edges, so the frame difference is noise even when most of the picture moves."""
    grad = np.zeros(cur.shape[:2], np.float32)
    unclipped = np.ones(cur.shape[:2], bool)
    for img in (prev, cur):
        g = np.asarray(img.mean(axis=2), np.float32)
        mag = np.abs(cv2.Sobel(g, cv2.CV_32F, 1, 0)) + np.abs(cv2.Sobel(g, cv2.CV_32F, 0, 1))
        np.maximum(grad, mag, out=grad)
        unclipped &= (img.min(axis=2) > 2 / 255) & (img.max(axis=2) < 253 / 255)  # any channel clipped: no noise
    # averaged over a wider window than the statistic's, so a pixel's own noise hardly decides its flatness
    wide = 2 * window + 1
    grad = np.asarray(cv2.boxFilter(grad, -1, (wide, wide), borderType=cv2.BORDER_REFLECT), np.float32)
    if unclipped.sum() < MIN_FLAT:
        unclipped[:] = True
    # up to half as much again as the flattest share's gradient: in a flat area the gradient is the noise's, and
    # ranking the pixels within it would pick those where the noise happens to be low
    return np.asarray(unclipped & (grad <= 1.5 * np.quantile(grad[unclipped], FLAT_SHARE)), bool)


def noise_figures(stat: F32, flat: NDArray[np.bool_]) -> tuple[float, float]:
    """Level (median) and spread (median absolute deviation) of a change statistic over the flat pixels."""
    v = stat[flat] if flat.sum() >= MIN_FLAT else stat[::SUBSAMPLE, ::SUBSAMPLE].ravel()
    level = float(np.median(v))
    return level, float(np.median(np.abs(v - level)))


@dataclass
class FrameChange:
    """Every camera's changed pixels between two frame sets, with the noise each test used."""

    changed: dict[str, NDArray[np.uint8]]  # 1: changed (dilated by the window), per camera
    sigma: dict[str, float]  # sensor noise, 8-bit levels
    share: dict[str, float]  # share of the camera's pixels that changed


@dataclass
class HalfPictures:
    """A frame set's pictures at half size (:func:`half`), made once each: what the change test reads of the
    frame set before, and all the temporal state keeps of its pictures (a quarter of the pixels in float,
    not the frame set's pictures and their grey; issue 24: a chunk's memory)."""

    names: list[str]
    pictures: dict[str, F32] = field(default_factory=dict)
    grid: Grid | None = None  # where the ones not made yet come from (let go of by :meth:`made`)

    @classmethod
    def of(cls, grid: Grid) -> HalfPictures:
        return cls(list(grid.names), {}, grid)

    def __getitem__(self, name: str) -> F32:
        if name not in self.pictures:
            assert self.grid is not None, f"the half-size picture of {name} was not made"
            self.pictures[name] = half(self.grid.images[name])
        return self.pictures[name]

    def take(self, name: str) -> F32:
        """Camera ``name``'s picture, no longer held here (made if it was not)."""
        picture = self[name]
        del self.pictures[name]
        return picture

    def made(self) -> HalfPictures:
        """Every camera's picture made and the frame set let go of."""
        for name in self.names:
            self[name]
        self.grid = None
        return self


def half(img: F32) -> F32:
    """A picture at half size (area average): the change test looks at windows of pixels, and a quarter of the
    pixels is a quarter of the work."""
    h, w = img.shape[:2]
    return np.asarray(cv2.resize(img, ((w + 1) // 2, (h + 1) // 2), interpolation=cv2.INTER_AREA), np.float32)


def frame_change(
    prev: Grid | HalfPictures, cur: Grid, history: dict[str, NoiseHistory], window: int, sigmas: float
) -> FrameChange:
    """The change of every camera present in both frame sets (``prev`` may be the half-size pictures kept of
    it); adds this pair's noise figures to ``history``. The test runs at half size (``window`` is in
    full-size pixels), its answer is given at full size.

    One camera at a time, and each of ``prev``'s pictures is let go of once read (``HalfPictures.take``), as
    are ``cur``'s: both frame sets' half-size pictures were 0.45 GiB held through the frame set's depth at
    3840x2160 (issue 24; the resident peak, glibc's, did not fall with them: see the README). The next frame
    set's earlier pictures are made again from the grid when it is done (``Temporal.advance``): the same
    values, 9 resizes a frame set."""
    changed, sigma, share = {}, {}, {}
    win = max(3, window // 2 | 1)
    kernel = np.ones((win, win), np.uint8)
    h, w = cur.shape
    before = prev if isinstance(prev, HalfPictures) else HalfPictures.of(prev)
    now = HalfPictures.of(cur)
    for name in cur.names:
        if name not in before.names:
            continue
        a, b = before.take(name), now.take(name)
        flat = flat_pixels(a, b, win)
        stat = change_statistic(a, b, win, flat)
        del a, b
        hist = history.setdefault(name, NoiseHistory())
        hist.add(*noise_figures(stat, flat))
        moved = (stat > hist.threshold(sigmas)).astype(np.uint8)
        # the window's statistic reaches half a window around a change: the pixels it reached changed too
        grown = cv2.dilate(moved, kernel)
        changed[name] = np.asarray(cv2.resize(grown, (w, h), interpolation=cv2.INTER_NEAREST), np.uint8)
        sigma[name] = hist.sigma()
        share[name] = float(changed[name].mean())
    return FrameChange(changed, sigma, share)


def still_in_every_view(change: FrameChange, grid: Grid, ref: str, disparity: F32) -> NDArray[np.bool_]:
    """Pixels of ``ref`` (with a finite ``disparity``) unchanged in ``ref`` and in every other camera that sees
    them: the point at disparity d lies at (x - d dx, y - d dy) in a camera at offset (dx, dy)."""
    have = np.isfinite(disparity)
    still = have & (change.changed[ref] == 0)
    rows, cols = np.flatnonzero(still.any(axis=1)), np.flatnonzero(still.any(axis=0))
    if not rows.size:
        return still
    # only the box of the pixels that can stay still: a whole frame's coordinate grids and maps were 0.3 GiB
    # at 3840x2160 (issue 24); each pixel's map is the same number either way
    y0, y1, x0, x1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
    box = still[y0:y1, x0:x1]
    gy = np.arange(y0, y1, dtype=np.float32)[:, None]
    gx = np.arange(x0, x1, dtype=np.float32)[None, :]
    part = disparity[y0:y1, x0:x1]
    d = np.where(have[y0:y1, x0:x1], part, 0.0).astype(np.float32)
    ox, oy = grid.offsets[ref]
    for name, moved in change.changed.items():
        if name == ref:
            continue
        rx, ry = grid.offsets[name][0] - ox, grid.offsets[name][1] - oy
        if abs(rx) < 1e-9 and abs(ry) < 1e-9:
            continue
        mx, my = gx - d * np.float32(rx), gy - d * np.float32(ry)
        # outside the camera's picture: it does not see the point, so it has no say (border value 0)
        seen_moved = cv2.remap(moved, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        box &= seen_moved == 0
    return still
