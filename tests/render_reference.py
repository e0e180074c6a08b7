"""The renderer as it was first written with numpy and OpenCV calls (``np.maximum.at`` for the splat,
``cv2.remap`` for the samples, ``cv2.blendLinear`` for the running mean), kept as the reference the compiled
kernels in ``rigctl.render.kernels`` are checked against. Slow (about 15x the kernels), clear, and built from
library calls whose behaviour is documented, so a disagreement points at the kernels."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
NONE = np.float32(-1e6)
RING = 2


class Src:
    """A source for the reference: RGBA (u8), disparity with NONE, and its half-resolution samples."""

    def __init__(self, name: str, offset: tuple[float, float], rgb: F32, alpha: F32, disparity: F32) -> None:
        self.name, self.offset = name, offset
        self.rgba = np.empty((*rgb.shape[:2], 4), np.uint8)
        self.rgba[..., :3] = np.clip(rgb * 255.0 + 0.5, 0, 255)
        self.rgba[..., 3] = np.clip(alpha * 255.0 + 0.5, 0, 255)
        self.disparity = np.where(np.isfinite(disparity), disparity, NONE).astype(np.float32)
        half = self.disparity[::2, ::2]
        ys, xs = np.nonzero(half > NONE)
        self.sx, self.sy = (xs * 2).astype(np.float32), (ys * 2).astype(np.float32)
        self.sd = half[ys, xs].copy()


def fill_background_side(t: F32, max_gap: int) -> F32:
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


class ReferenceRenderer:
    def __init__(self, sources: list[Src], taps: int = 4, agree_px: float = 1.5) -> None:
        self.sources, self.taps, self.agree_px = sources, taps, agree_px
        h, w = sources[0].disparity.shape
        self.shape = (h, w)
        self.hl, self.wl = (h + 1) // 2, (w + 1) // 2
        spread = [float(s.sd.max() - s.sd.min()) for s in sources if s.sd.size]
        self.max_gap = int(max(spread, default=0.0) * 1.5 / 2) + 4

    def nearest(self, u: float, v: float, exclude: tuple[str, ...] = ()) -> list[Src]:
        pool = [s for s in self.sources if s.name not in exclude]
        pool.sort(key=lambda s: ((s.offset[0] - u) ** 2 + (s.offset[1] - v) ** 2, s.name))
        return pool[: self.taps]

    def splat(self, u: float, v: float, sources: list[Src]) -> F32:
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
        t = fill_background_side(t, self.max_gap)
        t = np.ascontiguousarray(fill_background_side(t.T, self.max_gap).T)
        ring = cv2.dilate(t, np.ones((2 * RING + 1, 2 * RING + 1), np.uint8))
        return np.where(t > NONE, t, ring)

    def render(self, u: float, v: float, exclude: tuple[str, ...] = ()) -> tuple[F32, F32]:
        """(RGBA in [0, 1], full-resolution target disparity with NONE where there is none)."""
        sources = self.nearest(u, v, exclude)
        h, w = self.shape
        low = self.splat(u, v, sources)
        d = np.asarray(cv2.resize(low, (2 * self.wl, 2 * self.hl), interpolation=cv2.INTER_NEAREST)[:h, :w])
        xg, yg = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        blended: Any = None
        wsum: Any = None
        for s in sources:
            du, dv = s.offset[0] - u, s.offset[1] - v
            closeness = 1.0 / (float(np.hypot(du, dv)) + 0.1) ** 2
            mx, my = cv2.scaleAdd(d, -du, xg), cv2.scaleAdd(d, -dv, yg)
            colour = cv2.remap(s.rgba, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            seen = cv2.remap(
                s.disparity, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=float(NONE)
            )
            agree = cv2.addWeighted(cv2.absdiff(seen, d), -closeness / self.agree_px, seen, 0.0, closeness)
            wgt = cv2.max(agree, np.full_like(agree, closeness * 1e-3))
            if blended is None:
                blended, wsum = colour, wgt
            else:
                blended = cv2.blendLinear(blended, colour, wsum, wgt)
                wsum = cv2.add(wsum, wgt)
        valid = (d > NONE).astype(np.uint8)
        rgba = cv2.bitwise_and(blended, blended, mask=valid).astype(np.float32) * np.float32(1 / 255)
        return rgba, d
