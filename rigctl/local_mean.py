"""Normalised convolution for the soft key (``rigctl.keying``): the weighted local mean of values around the
pixels asked for, at the first of several blur widths that has weight nearby. A fine blur is made only on the
tiles the pixels lie in, a wide one at a coarser scale, each the values OpenCV gives over the frame, bit for
bit (issue 24: the write's time and memory)."""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

COMPILED = True  # the whole-block shrink of a wide blur compiled (local_mean_kernels.py); False: numpy and OpenCV
TILE = 32  # px: the fine blurs are made on the tiles of the frame the key reads (the edge band's)
SHRINK_ROWS = 128  # rows of the frame shrunk at a time for a wide blur (whole blocks)


class LocalMean:
    """Normalised convolution: the weighted local mean of ``values`` (H x W x C) at the first of ``sigmas``
    that has weight nearby, else the next. A blur is made only when some pixel asked for needs it: a fine one
    on the :data:`TILE` x :data:`TILE` tiles the pixels asked for lie in (the edge band is a few % of a frame),
    each run of tiles blurred with the blur's reach around it, which gives OpenCV's values over the frame there
    bit for bit; the wide ones at a coarser scale, read at the pixels asked for (:meth:`at`) as OpenCV's
    bilinear enlargement would give them, without enlarging the frame."""

    def __init__(self, values: F32, weight: NDArray[np.float32 | np.uint8], sigmas: tuple[float, ...]) -> None:
        """``values``: H x W x C+1, the last channel ones (:func:`with_ones`, shared by every mean); ``weight``:
        H x W, float32 or bytes (0 and 1: the same products in a quarter of the memory)."""
        self.shape = weight.shape
        self.sigmas = sigmas
        self.values, self.weight = values, weight  # their product made where read: 133 MB a mean at 4K
        self.fields: dict[int, F32] = {}  # a wide field (coarse), or a fine one's made tiles (or its frame)
        self.todo: dict[int, NDArray[np.bool_]] = {}  # a fine field's tiles not blurred yet
        self.slots: dict[int, NDArray[np.int32]] = {}  # where each tile of a fine field is held (-1: nowhere)
        self.coarse: dict[int, F32] = {}  # a wide field's shrunk values, made on the cells read (_wide_cells)
        self.have: dict[int, NDArray[np.bool_]] = {}  # which of its cells are made

    def weighted(self, box: tuple[int, int, int, int] | None = None) -> F32:
        """The values times the weight over ``box`` (top, bottom, left, right; default the frame), bit for bit."""
        top, bottom, left, right = box if box is not None else (0, self.shape[0], 0, self.shape[1])
        out = np.empty((bottom - top, right - left, self.values.shape[2]), np.float32)
        np.multiply(self.values[top:bottom, left:right], self.weight[top:bottom, left:right, None], out=out)
        return out

    def made(self, k: int, idx: NDArray[np.intp]) -> LocalMean:
        """This mean with its blur ``k`` made where ``idx`` will read it (to make it in a thread of the
        caller's choosing)."""
        self.field(k, idx)
        return self

    def scale(self, k: int) -> int:
        """1 / the scale blur ``k`` is made at (:func:`coarse_scale`)."""
        return coarse_scale(self.sigmas[k], *self.shape)

    def field(self, k: int, idx: NDArray[np.intp]) -> F32:
        """The blurred weighted values at ``sigmas[k]``, right at least at the flat pixel indices ``idx``:
        over the frame, or at 1 / scale of it."""
        sigma, scale = self.sigmas[k], self.scale(k)
        if scale == 1:
            return self._fine(k, idx)
        h, w = self.shape
        if COMPILED and scale >= 3 and not (h % scale or w % scale) and _compilable(self.values, self.weight):
            return self._wide_cells(k, idx)
        if k not in self.fields:
            self.fields[k] = np.asarray(cv2.GaussianBlur(self.shrunk(scale), (0, 0), sigma / scale), np.float32)
        return self.fields[k]

    def shrunk(self, scale: int) -> F32:
        """The weighted values at 1 / ``scale`` (OpenCV's area average). Where ``scale`` divides the frame, each
        value is its block's mean alone: made in bands of whole blocks, the frame's values bit for bit without
        the frame's weighted values at once (issue 24: 133 MB at 4K, at the write's peak); for a scale of 3 or
        more (where OpenCV sums each block in scalar code) compiled, in one pass that multiplies and sums,
        the same bits in about half the time (the soft key is the write's critical path)."""
        h, w = self.shape
        if h % scale or w % scale:
            small = cv2.resize(self.weighted(), (max(1, w // scale), max(1, h // scale)), interpolation=cv2.INTER_AREA)
            return np.asarray(small, np.float32)
        out = np.empty((h // scale, w // scale, self.values.shape[2]), np.float32)
        if COMPILED and scale >= 3 and _compilable(self.values, self.weight):
            from rigctl.local_mean_kernels import shrunk_product  # compiled on first use

            shrunk_product(self.values, self.weight, scale, out, (0, out.shape[0]), (0, out.shape[1]))  # one pass
            return out
        for y0 in range(0, h, rows := -(-SHRINK_ROWS // scale) * scale):
            part = self.weighted((y0, min(h, y0 + rows), 0, w))
            band = out[y0 // scale : (y0 + len(part)) // scale]
            band[...] = cv2.resize(part, (w // scale, len(band)), interpolation=cv2.INTER_AREA)
        return out

    def _wide_cells(self, k: int, idx: NDArray[np.intp]) -> F32:
        """Wide field ``k`` (a scale that divides the frame, compiled) right at the pixels ``idx`` reads: only
        the coarse cells the blur reaches from their box are shrunk (more are added when later pixels need
        them), the rest left 0, and the coarse frame blurred (small), so each value read is the whole frame's
        bit for bit. A wide blur is read by few pixels of the band (a few hundred of 10^5 at 1920x1080, where the
        screen is farther than the fine blur reaches), which the frame's shrink, three of the soft key's
        five, cost a quarter of its time for (issue 24: the soft key is the write's critical path)."""
        from rigctl.local_mean_kernels import shrunk_product  # compiled on first use

        h, w = self.shape
        scale = self.scale(k)
        hs, ws = h // scale, w // scale
        small, have = self.coarse.get(k), self.have.get(k)
        if small is None or have is None:
            small = np.zeros((hs, ws, self.values.shape[2]), np.float32)
            have = np.zeros((hs, ws), bool)
            self.coarse[k], self.have[k] = small, have
        if not len(idx):
            return self.fields.get(k, small)
        ys, xs = np.divmod(idx, w)
        reach = int(np.ceil(4 * self.sigmas[k] / scale)) + 1  # past OpenCV's kernel radius for float
        # the coarse cells bilinear reads (and the next), and the blur's reach around them
        top, bottom = (int(linear(v, hs, h)[0][0]) for v in (ys.min(keepdims=True), ys.max(keepdims=True)))
        left, right = (int(linear(v, ws, w)[0][0]) for v in (xs.min(keepdims=True), xs.max(keepdims=True)))
        r0, r1 = max(0, top - reach), min(hs, bottom + 1 + reach + 1)
        c0, c1 = max(0, left - reach), min(ws, right + 1 + reach + 1)
        rows, cols = np.nonzero(~have[r0:r1, c0:c1])
        if len(rows) or k not in self.fields:
            if len(rows):
                a, b, c, d = (
                    r0 + int(rows.min()),
                    r0 + int(rows.max()) + 1,
                    c0 + int(cols.min()),
                    c0 + int(cols.max()) + 1,
                )
                shrunk_product(self.values, self.weight, scale, small, (a, b), (c, d))
                have[a:b, c:d] = True
            self.fields[k] = np.asarray(cv2.GaussianBlur(small, (0, 0), self.sigmas[k] / scale), np.float32)
        return self.fields[k]

    def _fine(self, k: int, idx: NDArray[np.intp]) -> F32:
        """Field ``k`` at full resolution, blurred on the tiles ``idx`` lies in that were not blurred before:
        each run of them along a row of tiles with the Gaussian's reach around it (OpenCV's kernel for float:
        8 sigma + 1 taps, rounded), so every value in the run is the frame's blur bit for bit (the frame's own
        edges are the run's). Only the tiles made are held (N x TILE x TILE x C, where :attr:`slots` says;
        issue 24: a frame-sized field committed a page wherever a tile's row touched it, 0.12 GiB a field at
        4K, at the write's peak). Over the frame at once (H x W x C) when the runs and their margins would blur
        half as many pixels as the frame has or more (scattered tiles: specks of noise on a screen)."""
        h, w = self.shape
        c = self.values.shape[2]
        if k not in self.fields:
            self.todo[k] = np.ones((-(-h // TILE), -(-w // TILE)), bool)
            self.slots[k] = np.full(self.todo[k].shape, -1, np.int32)
            self.fields[k] = np.empty((0, TILE, TILE, c), np.float32)
        todo, slots = self.todo[k], self.slots[k]
        need = np.zeros_like(todo)
        ys, xs = np.divmod(idx, w)
        need[ys // TILE, xs // TILE] = True
        need &= todo
        if not need.any():
            return self.fields[k]
        sigma = self.sigmas[k]
        reach = int(np.ceil(4 * sigma)) + 1  # past the kernel's half width, whichever way OpenCV rounds it
        # a run starts a whole number of tiles into the frame, so its rows end as the frame's do, in the same
        # vector lanes (OpenCV's last few pixels of a row, past its vector loop, may round apart): its margin
        # on the left is the reach rounded up to whole tiles
        before = -(-reach // TILE) * TILE
        runs = []  # (ty, a, b): tiles a..b-1 of row ty, and (top, bottom, left, right) of what is blurred
        for ty in np.flatnonzero(need.any(1)).tolist():
            ends = np.flatnonzero(np.diff(np.concatenate([[False], need[ty], [False]]).astype(np.int8))).tolist()
            y0, y1 = ty * TILE, min(h, ty * TILE + TILE)
            for a, b in zip(ends[0::2], ends[1::2], strict=True):
                blurred = (max(0, y0 - reach), min(h, y1 + reach), max(0, a * TILE - before), min(w, b * TILE + reach))
                runs.append(((ty, a, b), blurred))
        if 2 * sum((bottom - top) * (right - left) for _, (top, bottom, left, right) in runs) >= h * w:
            self.fields[k] = np.asarray(cv2.GaussianBlur(self.weighted(), (0, 0), sigma), np.float32)
            todo[...] = False
            return self.fields[k]
        held = self.fields[k]
        new = np.empty((int(need.sum()), TILE, TILE, c), np.float32)
        slots[need] = len(held) + np.arange(len(new), dtype=np.int32)  # in frame order, as the runs are
        n = 0
        for (ty, a, b), (top, bottom, left, right) in runs:
            part = cv2.GaussianBlur(self.weighted((top, bottom, left, right)), (0, 0), sigma)
            y0, x0 = ty * TILE, a * TILE
            rows = part[y0 - top : min(h, y0 + TILE) - top, x0 - left : min(w, b * TILE) - left]
            strip = np.zeros((TILE, (b - a) * TILE, c), np.float32)  # the frame's edge: the rest is not read
            strip[: rows.shape[0], : rows.shape[1]] = rows
            new[n : n + b - a] = strip.reshape(TILE, b - a, TILE, c).transpose(1, 0, 2, 3)
            n += b - a
        self.fields[k] = np.concatenate([held, new]) if len(held) else new
        todo &= ~need
        return self.fields[k]

    def sample(self, k: int, idx: NDArray[np.intp]) -> F32:
        """Field ``k`` at the frame's flat pixel indices ``idx`` (N x C+1)."""
        field = self.field(k, idx)
        h, w = self.shape
        if self.scale(k) == 1 and field.ndim == 3:  # made over the frame
            return field.reshape(-1, field.shape[2])[idx]
        if self.scale(k) == 1:
            ys, xs = np.divmod(idx, w)
            return field[self.slots[k][ys // TILE, xs // TILE], ys % TILE, xs % TILE]
        hs, ws = field.shape[:2]
        y, x = np.divmod(idx, w)
        x0, fx = linear(x, ws, w)
        y0, fy = linear(y, hs, h)
        dx = (x0 < ws - 1).astype(np.intp)
        row0 = y0 * ws + x0
        row1 = row0 + ws * (y0 < hs - 1)
        flat = field.reshape(-1, field.shape[2])
        fx, fy = fx[:, None], fy[:, None]
        top = flat[row0] * (1 - fx) + flat[row0 + dx] * fx
        bottom = flat[row1] * (1 - fx) + flat[row1 + dx] * fx
        return np.asarray(top * (1 - fy) + bottom * fy, np.float32)

    def at(self, idx: NDArray[np.intp]) -> tuple[F32, F32]:
        """The means at the flat pixel indices ``idx`` (N x C), and where there was any weight (N, 0/1)."""
        c = self.values.shape[2] - 1
        out = np.zeros((len(idx), c), np.float32)
        done = np.zeros(len(idx), bool)
        for k in range(len(self.sigmas)):
            rest = np.flatnonzero(~done)
            if not len(rest):
                break
            at = self.sample(k, idx[rest])
            take = at[:, -1] > 0.02
            out[rest[take]] = at[take, :-1] / at[take, -1:]
            done[rest[take]] = True
        return out, done.astype(np.float32)


def coarse_scale(sigma: float, h: int, w: int) -> int:
    """1 / the scale a blur of ``sigma`` is made at on an H x W frame: a wide blur at a coarser scale, the
    same field in a fraction of the time. About sigma / 4 (a blur of 4 px or more there); the largest scale
    that divides the frame both ways above half that (1920x1080 at sigma 64: 15, not 16), so that each coarse
    value is its block's mean alone (:meth:`LocalMean.shrunk`), else sigma / 4."""
    most = max(1, int(sigma // 4))
    common = math.gcd(h, w)
    return next((s for s in range(most, most // 2, -1) if common % s == 0), most)


def _compilable(values: NDArray[np.generic], weight: NDArray[np.generic]) -> bool:
    """What the compiled shrink takes: float32 H x W x C values and an H x W weight of bytes or float32."""
    return (
        values.dtype == np.float32
        and values.ndim == 3
        and weight.dtype in (np.uint8, np.float32)
        and weight.shape == values.shape[:2]
    )


def linear(dst: NDArray[np.intp], small: int, size: int) -> tuple[NDArray[np.intp], F32]:
    """Where OpenCV's bilinear resize of ``small`` pixels to ``size`` reads destination pixel ``dst``: the
    left source pixel and the weight of the right one (half-pixel centres, clamped at both ends)."""
    src = (dst + 0.5) * (small / size) - 0.5
    left = np.floor(src).astype(np.intp)
    frac = (src - left).astype(np.float32)
    frac[left < 0] = 0.0
    frac[left >= small - 1] = 0.0
    return np.clip(left, 0, small - 1), frac


def with_ones(values: F32) -> F32:
    """H x W x C values with a channel of ones after them (what :class:`LocalMean` weighs)."""
    out = np.empty((*values.shape[:2], values.shape[2] + 1), np.float32)
    out[..., :-1] = values
    out[..., -1] = 1.0
    return out


def local_mean(values: F32, weight: F32, sigmas: tuple[float, ...]) -> tuple[F32, F32]:
    """:class:`LocalMean` at every pixel (H x W x C, H x W)."""
    h, w = weight.shape
    out, done = LocalMean(with_ones(values), weight, sigmas).at(np.arange(h * w))
    return out.reshape(h, w, -1), done.reshape(h, w)
