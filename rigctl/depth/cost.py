"""The plane sweep's matching cost, shared with the cost-volume engine: locally normalised intensity
(invariant to the cameras' gain and offset differences), its absolute difference truncated at TRUNCATE, box
aggregated per view, and per pixel the best views kept (a point hidden from some cameras is seen by others:
occlusion-aware view selection), or the best side of the reference."""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import Grid, grey_of
from rigctl.depth.referee_kernels import keep_best, normalised, view_differences, window_means

F32 = NDArray[np.float32]
INVALID_COST = 1e3  # a view that cannot see the point (outside its image)
TRUNCATE = 1.5  # normalised-intensity difference above this is an occlusion or a mismatch, not more
COMPILED = True  # SweepLevel.costs_where by the compiled kernels; False: the OpenCV and numpy reference


def normalise(g: F32, win: int = 7) -> tuple[F32, F32]:
    """Locally normalised intensity, and the local standard deviation (texture)."""
    mean = cv2.boxFilter(g, -1, (win, win), borderType=cv2.BORDER_REFLECT)
    sq = cv2.boxFilter(g * g, -1, (win, win), borderType=cv2.BORDER_REFLECT)
    std = np.sqrt(np.maximum(sq - mean * mean, 0.0))
    return np.asarray((g - mean) / (std + 0.01), dtype=np.float32), np.asarray(std, dtype=np.float32)


NORMALISE_WIN = 7  # the local normalisation's window, px


def normalise_part(g: F32, part: tuple[int, int, int, int], win: int = NORMALISE_WIN) -> tuple[F32, F32]:
    """``normalise(g)`` cropped to ``part`` (y0, y1, x0, x1), made from that part and the window's reach
    around it (inside the frame) rather than from the frame (issue 24: a view's part is what is matched, and
    at 3840x2160 a whole frame's five temporaries are 165 MB). The same values: the window reads only the
    reach, the frame's own edges are reflected as before, and OpenCV's box sums of float run in double, exact
    for pictures of up to 10 bits, so a sum started elsewhere on the row is the same number
    (``tests/unit/test_cost_normalise.py``). The box sums by OpenCV, the rest in one compiled pass over the
    part only (``referee_kernels.normalised``: numpy's float32 operations in numpy's order, so the same
    bits) unless ``COMPILED`` is off."""
    y0, y1, x0, x1 = part
    h, w = g.shape
    m = win // 2
    a0, a1, b0, b1 = max(0, y0 - m), min(h, y1 + m), max(0, x0 - m), min(w, x1 + m)
    if not COMPILED:
        norm, std = normalise(np.ascontiguousarray(g[a0:a1, b0:b1]), win)
        rows, cols = slice(y0 - a0, y1 - a0), slice(x0 - b0, x1 - b0)
        return np.ascontiguousarray(norm[rows, cols]), np.ascontiguousarray(std[rows, cols])
    around = np.ascontiguousarray(g[a0:a1, b0:b1], np.float32)
    mean = np.asarray(cv2.boxFilter(around, -1, (win, win), borderType=cv2.BORDER_REFLECT), np.float32)
    sq = np.asarray(cv2.boxFilter(around * around, -1, (win, win), borderType=cv2.BORDER_REFLECT), np.float32)
    norm = np.empty((y1 - y0, x1 - x0), np.float32)
    std = np.empty((y1 - y0, x1 - x0), np.float32)
    normalised(around, mean, sq, (y0 - a0, x0 - b0), norm, std)
    return norm, std


PART_MARGIN = 4  # px around a view's part beyond the bilinear sample's pixels (see :func:`view_part`)


def view_part(
    box: tuple[int, int, int, int],
    frame: tuple[int, int],
    rel: tuple[float, float],
    reach: tuple[float, float] | None,
    margin: int = PART_MARGIN,
) -> tuple[int, int, int, int]:
    """(y0, y1, x0, x1) of a view at baseline ``rel`` (its frame ``frame``, h x w) that disparities within
    ``reach`` (px of this scale) sample from ``box``: the bilinear sample's second pixel and ``margin`` more,
    clipped to the frame (at least its edge row or column); the whole frame without ``reach``. A sample there is
    the same as in the whole view."""
    h, w = frame
    if reach is None:
        return 0, h, 0, w
    y0, y1, x0, x1 = box
    sx = [d * rel[0] for d in reach]
    sy = [d * rel[1] for d in reach]
    a0, b0 = max(0, math.floor(y0 - max(sy)) - margin), max(0, math.floor(x0 - max(sx)) - margin)
    a1, b1 = min(h, math.ceil(y1 - min(sy)) + margin), min(w, math.ceil(x1 - min(sx)) + margin)
    # every sample beyond the frame (a view that sees none of the box at these disparities): the frame's edge
    # pixel nearest them, a part of one row or column rather than none, as the whole view gives beyond its edge
    a0, b0 = min(a0, h - 1), min(b0, w - 1)
    return a0, max(a1, a0 + 1), b0, max(b1, b0 + 1)


class SweepLevel:
    """Normalised images of the reference crop and of every view, at one scale. ``reach`` (lo, hi), px of
    the full resolution: the disparities it will be asked for; each view then keeps only the part of its
    normalised image they reach from the crop (``org``: its top-left pixel), not the frame (issue 24)."""

    def __init__(
        self,
        grid: Grid,
        ref: str,
        views: list[str],
        scale: float,
        box: tuple[int, int, int, int],
        reach: tuple[float, float] | None = None,
    ) -> None:
        self.scale = scale
        y0, y1, x0, x1 = (round(v * scale) for v in box)
        self.box = (y0, y1, x0, x1)
        self.size = (x1 - x0, y1 - y0)
        self.norm: dict[str, F32] = {}
        self.org: dict[str, tuple[int, int]] = {}
        ox, oy = grid.offsets[ref]
        self.rel = {n: (grid.offsets[n][0] - ox, grid.offsets[n][1] - oy) for n in views}
        self.views = views
        scaled = None if reach is None else (reach[0] * scale, reach[1] * scale)
        for n in [ref, *views]:  # one camera at a time: its grey and whole normalised image go before the next
            if scale == 1.0:  # the grey's rows that the part and the normalisation's window read, alone
                self.h, self.w = grid.shape
                part = self.box if n == ref else view_part(self.box, grid.shape, self.rel[n], scaled)
                top, end = max(0, part[0] - NORMALISE_WIN // 2), min(self.h, part[1] + NORMALISE_WIN // 2)
                g = grey_of(grid.images, n, (top, end))
            else:
                g = grey_of(grid.images, n)
                g = np.asarray(cv2.resize(g, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA), np.float32)
                self.h, self.w = g.shape
                top = 0
                part = self.box if n == ref else view_part(self.box, g.shape, self.rel[n], scaled)
            rows = (part[0] - top, part[1] - top, part[2], part[3])  # the part in ``g``
            if n == ref:
                self.ref, self.texture = normalise_part(g, rows)
                self.bright = np.ascontiguousarray(g[rows[0] : rows[1], x0:x1])
                continue
            self.org[n] = (part[0], part[2])
            self.norm[n] = normalise_part(g, rows)[0]
            del g

    def cost_const(self, d: float, win: int) -> F32:
        """(views, h, w) aggregated cost at one disparity for every pixel."""
        y0, y1, x0, x1 = self.box
        out = np.empty((len(self.views), y1 - y0, x1 - x0), np.float32)
        xs = np.arange(x0, x1, dtype=np.float32)
        ys = np.arange(y0, y1, dtype=np.float32)
        for i, n in enumerate(self.views):
            rx, ry = self.rel[n]
            M = np.array([[1, 0, x0 - d * rx], [0, 1, y0 - d * ry]], np.float32)
            M[1, 2] -= np.float32(self.org[n][0])  # in the view's part
            M[0, 2] -= np.float32(self.org[n][1])
            warped = cv2.warpAffine(
                self.norm[n],
                M,
                self.size,
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_REPLICATE,
            )
            ad = np.minimum(np.abs(warped - self.ref), TRUNCATE)
            agg = cv2.boxFilter(ad, -1, (win, win), borderType=cv2.BORDER_REFLECT)
            inside_x = (xs - d * rx >= 0) & (xs - d * rx <= self.w - 1)
            inside_y = (ys - d * ry >= 0) & (ys - d * ry <= self.h - 1)
            agg[~inside_y, :] = INVALID_COST
            agg[:, ~inside_x] = INVALID_COST
            out[i] = agg
        return out

    def cost_map(self, D: F32, win: int) -> F32:
        """(views, h, w) aggregated cost at a per-pixel disparity map D (crop-sized)."""
        y0, y1, x0, x1 = self.box
        gy, gx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
        out = np.empty((len(self.views), y1 - y0, x1 - x0), np.float32)
        for i, n in enumerate(self.views):
            rx, ry = self.rel[n]
            mx = gx - D * np.float32(rx)
            my = gy - D * np.float32(ry)
            py, px = (np.float32(v) for v in self.org[n])
            warped = cv2.remap(self.norm[n], mx - px, my - py, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            ad = np.minimum(np.abs(warped - self.ref), TRUNCATE)
            agg = cv2.boxFilter(ad, -1, (win, win), borderType=cv2.BORDER_REFLECT)
            outside = (mx < 0) | (mx > self.w - 1) | (my < 0) | (my > self.h - 1)
            agg[outside] = INVALID_COST
            out[i] = agg
        return out

    def costs_where(self, candidates: list[F32], where: NDArray[np.bool_], win: int, keep: int) -> F32:
        """(candidates, pixels) combined cost of each candidate disparity map at the pixels of ``where`` only:
        each view is sampled at those pixels and their ``win`` neighbourhood, not over the whole crop. By the
        compiled kernels (``referee_kernels.py``) unless ``COMPILED`` is off (this numpy form, the reference)."""
        if COMPILED and win % 2 == 1 and min(where.shape) > win:  # else OpenCV's window (even: off-centre;
            return self._costs_where_compiled(candidates, where, win, keep)  # wider: reflected again)
        y0, _, x0, _ = self.box
        need = np.asarray(cv2.dilate(where.astype(np.uint8), np.ones((win, win), np.uint8)), bool)
        ys, xs = np.nonzero(need)
        n = ys.size
        width = 4096  # cv2.remap takes maps below 32767 in each dimension: lay the pixels out in rows
        rows = -(-n // width) if n else 1
        pad = rows * width - n
        gx = np.pad((xs + x0).astype(np.float32), (0, pad)).reshape(rows, width)
        gy = np.pad((ys + y0).astype(np.float32), (0, pad)).reshape(rows, width)
        ref_vals = self.ref[ys, xs]
        qy, qx = np.nonzero(where)
        nv = len(self.views)
        out = np.empty((len(candidates), qy.size), np.float32)
        # one view at a time through one image (issue 24: memory; four views as four channels held two
        # crop-sized four-channel images, 266 MB at 3840x2160, for the same sums: OpenCV's box filter sums
        # each channel on its own): only the pixels of ``need`` are ever written, the same ones for every
        # view, so the rest stays 0 as in one image per view
        dense = np.zeros(where.shape, np.float32)
        ad = np.empty((n, nv), np.float32)
        per_view = np.empty((nv, qy.size), np.float32)
        for ci, cand in enumerate(candidates):
            d = np.pad(cand[ys, xs], (0, pad)).reshape(rows, width)
            dq = cand[qy, qx]
            for vi, name in enumerate(self.views):
                rx, ry = self.rel[name]
                mx, my = gx - d * np.float32(rx), gy - d * np.float32(ry)
                py, px = (np.float32(v) for v in self.org[name])
                warped = cv2.remap(self.norm[name], mx - px, my - py, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                ad[:, vi] = warped.reshape(-1)[:n]
            np.subtract(ad, ref_vals[:, None], out=ad)
            np.abs(ad, out=ad)
            np.minimum(ad, TRUNCATE, out=ad)
            for vi in range(nv):
                dense[ys, xs] = ad[:, vi]
                per_view[vi] = cv2.boxFilter(dense, -1, (win, win), borderType=cv2.BORDER_REFLECT)[qy, qx]
            for vi, name in enumerate(self.views):
                rx, ry = self.rel[name]
                cx, cy = qx + x0 - dq * np.float32(rx), qy + y0 - dq * np.float32(ry)
                per_view[vi][(cx < 0) | (cx > self.w - 1) | (cy < 0) | (cy > self.h - 1)] = INVALID_COST
            out[ci] = combine(per_view, keep)
        return out

    def _costs_where_compiled(self, candidates: list[F32], where: NDArray[np.bool_], win: int, keep: int) -> F32:
        y0, _, x0, _ = self.box
        need = np.asarray(cv2.dilate(where.astype(np.uint8), np.ones((win, win), np.uint8)), bool)
        ys, xs = np.nonzero(need)
        qy, qx = np.nonzero(where)
        del need
        out = np.empty((len(candidates), qy.size), np.float32)
        per_view = np.empty((len(self.views), qy.size), np.float32)
        diff = np.zeros(where.shape, np.float32)  # written at the window pixels only, the same for every view
        for ci, cand in enumerate(candidates):
            c = np.ascontiguousarray(cand, np.float32)
            for vi, name in enumerate(self.views):
                org = (float(self.org[name][0]), float(self.org[name][1]))
                view_differences(self.norm[name], org, self.rel[name], self.ref, c, (y0, x0), ys, xs, TRUNCATE, diff)
                frame = (self.h, self.w)
                window_means(diff, c, self.rel[name], frame, (y0, x0), qy, qx, win, INVALID_COST, per_view[vi])
            keep_best(per_view, keep, INVALID_COST, out[ci])
        return out


def active_pixels(
    region: NDArray[np.bool_] | None, scale: float, shape: tuple[int, int] | None, grow: int
) -> NDArray[np.bool_] | None:
    """The pixels of a crop whose costs the sweeps compute, at ``scale`` (``shape``): ``region`` (the pixels
    estimated, full resolution) grown by ``grow`` full-resolution px (the context their estimates read: the
    guided filters of the sweep and the refinement, the windows), and by one coarse pixel more (the coarse
    estimate a full-resolution pixel starts from). None (every pixel) without a region."""
    if region is None:
        return None
    m = region
    if scale != 1.0:
        assert shape is not None
        small = cv2.resize(region.astype(np.float32), (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
        m, grow = small > 0, math.ceil(grow * scale) + 1
    k = np.ones((2 * grow + 1, 2 * grow + 1), np.uint8)
    return np.asarray(cv2.dilate(m.astype(np.uint8), k) > 0)


def exposure(g_ref: F32, g: F32, shift: tuple[float, float]) -> tuple[float, float]:
    """Gain and offset that match view ``g`` to the reference, from the part of the scene both show: the
    view moved by ``shift`` (the disparity range's centre times its baseline). Whole-image statistics would
    compare different content whenever the disparity is large (parallel cameras), and so depend on where
    the range lies. Identity when the two share too little."""
    h, w = g_ref.shape
    dx, dy = round(shift[0]), round(shift[1])
    if abs(dx) > w - 8 or abs(dy) > h - 8:
        return 1.0, 0.0
    # reference pixel (x, y) shows what the view shows at (x - dx, y - dy)
    a = g_ref[max(0, dy) : h + min(0, dy), max(0, dx) : w + min(0, dx)]
    b = g[max(0, -dy) : h + min(0, -dy), max(0, -dx) : w + min(0, -dx)]
    m_a, s_a, m_b, s_b = float(a.mean()), float(a.std()), float(b.mean()), float(b.std())
    gain = s_a / s_b if s_b > 1e-6 and s_a > 1e-6 else 1.0
    return gain, m_a - gain * m_b


def features(g: F32, part: tuple[int, int, int, int], out: F32 | None = None) -> F32:
    """(h, w, 3): intensity, d/dx and d/dy of ``g`` (a whole image) on ``part`` (y0, y1, x0, x1), the
    derivatives as the whole image's (the part taken with the one pixel around it that they read). Written
    into ``out`` when given (a view's place in a stack: no temporary of the three planes)."""
    y0, y1, x0, x1 = part
    h, w = g.shape
    a0, a1, b0, b1 = max(0, y0 - 1), min(h, y1 + 1), max(0, x0 - 1), min(w, x1 + 1)
    sub = np.ascontiguousarray(g[a0:a1, b0:b1])
    gx = cv2.Sobel(sub, cv2.CV_32F, 1, 0, ksize=1, scale=0.5, borderType=cv2.BORDER_REFLECT)
    gy = cv2.Sobel(sub, cv2.CV_32F, 0, 1, ksize=1, scale=0.5, borderType=cv2.BORDER_REFLECT)
    sl = (slice(y0 - a0, y1 - a0), slice(x0 - b0, x1 - b0))
    if out is None:
        out = np.empty((y1 - y0, x1 - x0, 3), np.float32)
    cv2.merge([sub[sl], gx[sl], gy[sl]], dst=out)
    return out


def side_groups(level: SweepLevel) -> list[list[int]]:
    """Views on each side of the reference (left, right, above, below): a point hidden by a foreground edge
    is hidden on one side only, so one of the sides sees it in every view."""
    eps = 1e-6
    sides = [
        [i for i, n in enumerate(level.views) if level.rel[n][0] < -eps],
        [i for i, n in enumerate(level.views) if level.rel[n][0] > eps],
        [i for i, n in enumerate(level.views) if level.rel[n][1] < -eps],
        [i for i, n in enumerate(level.views) if level.rel[n][1] > eps],
    ]
    return [g for g in sides if g]


def combine(costs: F32, keep: int, groups: list[list[int]] | None = None) -> F32:
    """Per pixel: the best side's mean cost (``groups``), or the mean of the ``keep`` smallest view costs
    (occluded views drop out)."""
    if groups:
        out = costs[groups[0]].mean(0)
        for g in groups[1:]:
            np.minimum(out, costs[g].mean(0), out=out)
        return np.asarray(out, dtype=np.float32)
    part = costs if keep >= costs.shape[0] else np.partition(costs, keep - 1, axis=0)[:keep]
    # views that cannot see the point (outside their image) do not count; a pixel only one view sees
    # is matched with that view alone
    seen = part < INVALID_COST * 0.5
    n = seen.sum(0)
    total = np.where(seen, part, 0).sum(0)
    return np.asarray(np.where(n > 0, total / np.maximum(n, 1), INVALID_COST), dtype=np.float32)
