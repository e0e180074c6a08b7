"""The renderer: backward warping of the nearest cameras into a novel view at (u, v) in the array plane.

For a target pixel x with disparity d (of one horizontal spacing), source camera i at (u_i, v_i) sees the
same point at x_i = x - d (u_i - u), y_i = y - d (v_i - v) (offsets in horizontal spacings, so dy/dx is
folded into v). Per view:

1. **target disparity** -- every source's disparity is forward-splatted into the target (at half
   resolution) with a depth test (the largest disparity, the nearest surface, wins); one-pixel cracks are
   closed; gaps left between two surfaces (disocclusions) are filled along rows, then columns, from the
   background side (the smaller disparity of the two ends), never across the keyed background;
2. **colour** -- each source is sampled at x_i with ``cv2.remap`` (bilinear, RGB + key alpha) and its own
   disparity at x_i (nearest); the source *sees* the point when that disparity agrees with the target's;
3. **blend** -- weight = closeness in the array plane (1 / (distance + 0.1)^2) times agreement
   (1 - |d_i(x_i) - d| / tolerance, floored at a small epsilon so that a point no source sees still gets the
   distance-weighted colour of its background-side fill). Alpha is blended like the colour; pixels with no
   target disparity (the keyed background) are transparent.

**GPU mapping.** Step 1 is a point-sprite pass per source into a depth-tested target (GL_MAX / depth
buffer), then two tiny fixed-radius passes (3x3 closing; the fill as a jump-flood or a bounded row search).
Steps 2-3 are one fragment shader with a fixed number of taps: for each of the K (default 4) sources one
bilinear RGBA texture fetch and one nearest disparity fetch at x_i, a few multiply-adds for the weight, and
the normalised sum. No loops depend on the data, so it maps one-to-one onto an HLSL/GLSL pixel shader.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

log = logging.getLogger(__name__)

F32 = NDArray[np.float32]
NONE = np.float32(-1e6)  # "no disparity" inside the renderer (PFM's +inf would poison interpolation)
TAPS = 4
RING = 2


@dataclass
class Source:
    """One source camera prepared for rendering (done once per frame: the GPU's texture upload)."""

    name: str
    offset: tuple[float, float]
    rgba: NDArray[np.uint8]  # H x W x 4: RGB and the key's alpha
    disparity: F32  # NONE where there is no estimate
    # valid half-resolution samples for the splat: full-resolution coordinates and disparity
    sx: F32 = field(default_factory=lambda: np.zeros(0, np.float32))
    sy: F32 = field(default_factory=lambda: np.zeros(0, np.float32))
    sd: F32 = field(default_factory=lambda: np.zeros(0, np.float32))


def prepare(name: str, offset: tuple[float, float], rgb: F32, alpha: F32, disparity: F32) -> Source:
    """A source from RGB in [0, 1], alpha in [0, 1] and disparity (+inf or NaN where there is none)."""
    rgba = np.empty((*rgb.shape[:2], 4), np.uint8)
    rgba[..., :3] = np.clip(rgb * 255.0 + 0.5, 0, 255)
    rgba[..., 3] = np.clip(alpha * 255.0 + 0.5, 0, 255)
    d = np.where(np.isfinite(disparity), disparity, NONE).astype(np.float32)
    half = d[::2, ::2]
    ys, xs = np.nonzero(half > NONE)
    return Source(name, offset, rgba, d, (xs * 2).astype(np.float32), (ys * 2).astype(np.float32), half[ys, xs].copy())


@dataclass
class Rendered:
    rgba: F32  # H x W x 4, straight (not premultiplied) colour and alpha in [0, 1]
    disparity: F32  # target disparity, +inf where none
    sources: list[str]


class Renderer:
    """Renders novel views of one frame from its prepared sources."""

    def __init__(self, sources: list[Source], taps: int = TAPS, agree_px: float = 1.5) -> None:
        if not sources:
            raise ValueError("no source cameras")
        self.sources = sources
        self.taps = taps
        self.agree_px = agree_px
        h, w = sources[0].disparity.shape
        self.shape = (h, w)
        self.hl, self.wl = (h + 1) // 2, (w + 1) // 2
        self.xgrid, self.ygrid = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        spread = [float(s.sd.max() - s.sd.min()) for s in sources if s.sd.size]
        self.max_gap = int(max(spread, default=0.0) * 1.5 / 2) + 4  # in half-resolution pixels

    def nearest(self, u: float, v: float, exclude: tuple[str, ...] = ()) -> list[Source]:
        pool = [s for s in self.sources if s.name not in exclude]
        pool.sort(key=lambda s: ((s.offset[0] - u) ** 2 + (s.offset[1] - v) ** 2, s.name))
        return pool[: self.taps]

    # ---- step 1: the target's disparity --------------------------------------------------------------
    def splat(self, u: float, v: float, sources: list[Source]) -> F32:
        """Half-resolution target disparity (NONE where no source lands), depth-tested, cracks closed and
        disocclusions filled from the background side."""
        hl, wl = self.hl, self.wl
        target = np.full(hl * wl, NONE, np.float32)
        for s in sources:
            du, dv = s.offset[0] - u, s.offset[1] - v
            xt = np.rint((s.sx + s.sd * du) * 0.5).astype(np.int32)
            yt = np.rint((s.sy + s.sd * dv) * 0.5).astype(np.int32)
            ok = (xt >= 0) & (xt < wl) & (yt >= 0) & (yt < hl)
            np.maximum.at(target, yt[ok] * wl + xt[ok], s.sd[ok])
        t = target.reshape(hl, wl)
        kernel = np.ones((3, 3), np.uint8)
        closed = cv2.erode(cv2.dilate(t, kernel), kernel)
        t = np.where(t > NONE, t, closed)
        t = _fill_background_side(t, self.max_gap)
        t = np.ascontiguousarray(_fill_background_side(t.T, self.max_gap).T)
        # a ring of RING half-resolution pixels around the subject: the key's soft edge, where the
        # estimate stops short; the sources' alpha decides how much of it shows
        ring = cv2.dilate(t, np.ones((2 * RING + 1, 2 * RING + 1), np.uint8))
        return np.where(t > NONE, t, ring)

    # ---- steps 2 and 3: sample and blend --------------------------------------------------------------
    def render(
        self, u: float, v: float, exclude: tuple[str, ...] = (), box: tuple[int, int, int, int] | None = None
    ) -> Rendered:
        """The view at (u, v) (horizontal spacings, relative to the grid's origin) from the ``taps`` nearest
        sources not in ``exclude``. ``box`` = (y0, y1, x0, x1) limits the work to a window."""
        sources = self.nearest(u, v, exclude)
        if not sources:
            raise ValueError("no source cameras left")
        h, w = self.shape
        low = self.splat(u, v, sources)
        dfull = np.asarray(
            cv2.resize(low, (2 * self.wl, 2 * self.hl), interpolation=cv2.INTER_NEAREST)[:h, :w], np.float32
        )
        y0, y1, x0, x1 = box or _valid_box(dfull)
        out = np.zeros((h, w, 4), np.float32)
        disp = np.full((h, w), np.inf, np.float32)
        if y1 <= y0 or x1 <= x0:
            return Rendered(out, disp, [s.name for s in sources])
        d = np.ascontiguousarray(dfull[y0:y1, x0:x1])
        xg, yg = self.xgrid[y0:y1, x0:x1], self.ygrid[y0:y1, x0:x1]
        blended: Any = None
        wsum: Any = None
        for s in sources:
            du, dv = s.offset[0] - u, s.offset[1] - v
            closeness = 1.0 / (float(np.hypot(du, dv)) + 0.1) ** 2
            mx = cv2.scaleAdd(d, -du, xg)
            my = cv2.scaleAdd(d, -dv, yg)
            colour = cv2.remap(s.rgba, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            seen = cv2.remap(
                s.disparity, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=float(NONE)
            )
            # agreement in [eps, 1], times closeness (OpenCV calls throughout: numpy's temporaries cost 10x)
            agree = cv2.addWeighted(cv2.absdiff(seen, d), -closeness / self.agree_px, seen, 0.0, closeness)
            wgt = cv2.max(agree, np.full_like(agree, closeness * 1e-3))
            if blended is None or wsum is None:
                blended, wsum = colour, wgt
            else:
                # running weighted mean: (W a + w b) / (W + w), in 8 bits like a texture blend
                blended = cv2.blendLinear(blended, colour, wsum, wgt)
                wsum = cv2.add(wsum, wgt)
        assert blended is not None
        valid = (d > NONE).astype(np.uint8)
        rgba = cv2.bitwise_and(blended, blended, mask=valid).astype(np.float32) * np.float32(1 / 255)
        out[y0:y1, x0:x1] = rgba
        disp[y0:y1, x0:x1] = np.where(valid > 0, d, np.inf)
        return Rendered(out, disp, [s.name for s in sources])


def _valid_box(d: F32) -> tuple[int, int, int, int]:
    valid = d > NONE
    rows = np.flatnonzero(valid.any(1))
    cols = np.flatnonzero(valid.any(0))
    if not rows.size:
        return 0, 0, 0, 0
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _fill_background_side(t: F32, max_gap: int) -> F32:
    """Fill runs of NONE along rows that lie between two valid pixels at most ``max_gap`` apart with the
    smaller (farther) of the two disparities: what a disocclusion uncovers is the background's."""
    h, w = t.shape
    valid = t > NONE
    if valid.all() or not valid.any():
        return t
    idx = np.broadcast_to(np.arange(w, dtype=np.int32), (h, w))
    left = np.maximum.accumulate(np.where(valid, idx, -1), axis=1)
    right = np.minimum.accumulate(np.where(valid, idx, w)[:, ::-1], axis=1)[:, ::-1]
    hole = ~valid & (left >= 0) & (right < w) & (right - left <= max_gap)
    if not hole.any():
        return t
    rows = np.broadcast_to(np.arange(h)[:, None], (h, w))
    out = t.copy()
    out[hole] = np.minimum(t[rows[hole], left[hole]], t[rows[hole], right[hole]])
    return out
