"""The renderer: backward warping of the nearest cameras into a novel view at (u, v) in the array plane.

For a target pixel x with disparity d (of one horizontal spacing), source camera i at (u_i, v_i) sees the
same point at x_i = x - d (u_i - u), y_i = y - d (v_i - v) (offsets in horizontal spacings, so dy/dx is
folded into v). Per view:

1. **target disparity** -- every source's disparity is forward-splatted into the target (at half
   resolution) with a depth test (the largest disparity, the nearest surface, wins); one-pixel cracks are
   closed; gaps left between two surfaces (disocclusions) are filled along rows, then columns, from the
   background side (the smaller disparity of the two ends), never across the keyed background;
2. **colour** -- each source is sampled at x_i (bilinear, RGB + key alpha, as ``cv2.remap`` would) and its
   own disparity at x_i (nearest); the source *sees* the point when that disparity agrees with the target's;
3. **blend** -- weight = closeness in the array plane (1 / (distance + 0.1)^2) times agreement
   (1 - |d_i(x_i) - d| / tolerance, floored at a small epsilon so that a point no source sees still gets the
   distance-weighted colour of its background-side fill). Alpha is blended like the colour; pixels with no
   target disparity (the keyed background) are transparent.

The passes are compiled kernels (``rigctl.render.kernels``): step 1 is one call at half resolution, steps
2-3 one call per full-resolution pixel; everything that is the same for every view of a frame (8-bit RGBA,
float32 disparity with ``NONE``, the disparity range) is prepared once per source by ``prepare``.

**GPU mapping.** Step 1 is a point-sprite pass per source into a depth-tested target (GL_MAX / depth
buffer), then tiny fixed-radius passes (3x3 closing; the fill as a jump-flood or a bounded row search; the
5x5 ring). Steps 2-3 are one fragment shader with a fixed number of taps: for each of the K (at most 4)
sources one bilinear RGBA texture fetch and one nearest disparity fetch at x_i, a few multiply-adds for the
weight, and the normalised sum. No loops depend on the data, so it maps one-to-one onto an HLSL/GLSL pixel
shader.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TypeVar

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.render import kernels
from rigctl.render.kernels import MAX_TAPS, NONE, RING

log = logging.getLogger(__name__)

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
A = TypeVar("A", bound=NDArray[np.generic])
TAPS = 4
_POOL: list[ThreadPoolExecutor] = []
_POOL_LOCK = threading.Lock()
_K3 = np.ones((3, 3), np.uint8)
_KRING = np.ones((2 * RING + 1, 2 * RING + 1), np.uint8)
__all__ = ["MAX_TAPS", "NONE", "RING", "TAPS", "Rendered", "Renderer", "Source", "prepare"]


@dataclass
class Source:
    """One source camera prepared for rendering (done once per frame: the GPU's texture upload)."""

    name: str
    offset: tuple[float, float]
    texture: NDArray[np.int64]  # H x W: RGB and the key's alpha, 8 bits each, 16 bits apart (kernels)
    disparity: F32  # NONE where there is no estimate
    half: F32  # its even rows and columns: the samples the splat takes
    spans: NDArray[np.int64]  # per row of ``half``: first and one past the last column with a disparity

    @property
    def span(self) -> tuple[float, float]:
        """(min, max) of the half-resolution disparities; (inf, -inf) when there are none."""
        valid = self.half[self.half > NONE]
        return (float(valid.min()), float(valid.max())) if valid.size else (np.inf, -np.inf)


def prepare(
    name: str, offset: tuple[float, float], rgb: F32, alpha: F32, disparity: F32, into: Source | None = None
) -> Source:
    """A source from RGB in [0, 1], alpha in [0, 1] and disparity (+inf or NaN where there is none); written
    over ``into``'s images when it is given and of the same size (a preview's next frame: as a GPU updates a
    texture, without fresh memory, whose first touch costs more than the preparation itself)."""
    h, w = alpha.shape
    if into is not None and into.texture.shape == (h, w):
        texture, disp, half, spans = into.texture, into.disparity, into.half, into.spans
    else:
        texture = np.empty((h, w), np.int64)
        disp = np.empty((h, w), np.float32)
        half = np.empty(((h + 1) // 2, (w + 1) // 2), np.float32)
        spans = np.empty((half.shape[0], 2), np.int64)
    kernels.prepare_source(_c32(rgb), _c32(alpha), _c32(disparity), texture, disp, half, spans)
    return Source(name, (float(offset[0]), float(offset[1])), texture, disp, half, spans)


def _packed(rgba: U8) -> NDArray[np.uint32]:
    """H x W x 4 bytes as H x W packed 32-bit pixels (no copy; R in the low byte on the little-endian
    machines Numba runs on)."""
    return rgba.view(np.uint32).reshape(rgba.shape[:2])


def _c32(a: NDArray[np.floating]) -> F32:
    return np.ascontiguousarray(a, dtype=np.float32)


@dataclass
class Rendered:
    """A view: 8-bit RGBA as the kernel wrote it (what a display takes) and the half-resolution target
    disparity; the float forms are made only when asked for."""

    rgba8: U8  # H x W x 4, straight (not premultiplied) colour and alpha
    low: F32  # half-resolution target disparity, NONE where none
    sources: list[str]
    target_ms: float = 0.0  # time of step 1 (splat, closing, fill, ring)
    shade_ms: float = 0.0  # time of steps 2-3

    @property
    def rgba(self) -> F32:
        """H x W x 4 in [0, 1]."""
        return self.rgba8.astype(np.float32) * np.float32(1 / 255)

    @property
    def disparity(self) -> F32:
        """The target disparity at full resolution (nearest), +inf where none."""
        h, w = self.rgba8.shape[:2]
        full = np.repeat(np.repeat(self.low, 2, axis=0), 2, axis=1)[:h, :w]
        return np.where(full > NONE, full, np.float32(np.inf)).astype(np.float32)


class Renderer:
    """Renders novel views of one frame from its prepared sources, on as many threads as the process may use
    (``threads``). One caller at a time: the scratch images of its two eyes are its own."""

    def __init__(self, sources: list[Source], taps: int = TAPS, agree_px: float = 1.5) -> None:
        if not sources:
            raise ValueError("no source cameras")
        if not 1 <= taps <= MAX_TAPS:
            raise ValueError(f"taps must be 1..{MAX_TAPS} (a fixed number per pixel), got {taps}")
        self.sources = sources
        self.taps = taps
        self.agree_px = agree_px
        h, w = sources[0].disparity.shape
        self.shape = (h, w)
        self.hl, self.wl = (h + 1) // 2, (w + 1) // 2
        spread = [s.span[1] - s.span[0] for s in sources if s.span[1] >= s.span[0]]
        self.max_gap = int(max(spread, default=0.0) * 1.5 / 2) + 4  # in half-resolution pixels
        self.threads = _cores()
        self._spaces = [_Workspace(self.hl, self.wl) for _ in range(2)]  # one per eye of a pair

    def nearest(self, u: float, v: float, exclude: tuple[str, ...] = ()) -> list[Source]:
        pool = [s for s in self.sources if s.name not in exclude]
        pool.sort(key=lambda s: ((s.offset[0] - u) ** 2 + (s.offset[1] - v) ** 2, s.name))
        return pool[: self.taps]

    def _taps(self, u: float, v: float, sources: list[Source]) -> tuple[int, F32, F32, F32]:
        n = len(sources)
        du = np.zeros(MAX_TAPS, np.float32)
        dv = np.zeros(MAX_TAPS, np.float32)
        du[:n] = [s.offset[0] - u for s in sources]
        dv[:n] = [s.offset[1] - v for s in sources]
        # a fitted grid puts a camera on the target's row 1e-16 off it: on it, its samples need one row
        du[np.abs(du) < 1e-6] = 0.0
        dv[np.abs(dv) < 1e-6] = 0.0
        closeness = (1.0 / (np.hypot(du, dv) + 0.1) ** 2).astype(np.float32)
        return n, du, dv, closeness

    @staticmethod
    def _padded(arrays: list[A]) -> tuple[A, ...]:
        """Always MAX_TAPS arrays (the unused ones repeat the first and are never read): one compiled
        kernel whatever the number of sources."""
        return tuple(arrays + [arrays[0]] * (MAX_TAPS - len(arrays)))

    # ---- step 1: the target's disparity --------------------------------------------------------------
    def _target(self, n: int, du: F32, dv: F32, sources: list[Source], ws: _Workspace) -> tuple[F32, F32]:
        """(splatted disparity with cracks closed and disocclusions filled, its ring): half resolution. The
        first is the view's own; the ring lives in ``ws`` until that workspace's next view."""
        low = np.empty((self.hl, self.wl), np.float32)
        halves, spans = self._padded([s.half for s in sources]), self._padded([s.spans for s in sources])
        kernels.splat(halves, spans, n, du, dv, low)
        cv2.erode(cv2.dilate(low, _K3, dst=ws.dilated), _K3, dst=ws.closed)
        kernels.close_and_fill(low, ws.closed, self.max_gap, ws.last)
        cv2.dilate(low, _KRING, dst=ws.ring)
        return low, ws.ring

    def splat(self, u: float, v: float, sources: list[Source]) -> F32:
        """Half-resolution target disparity (NONE where no source lands), depth-tested, cracks closed,
        disocclusions filled from the background side and the ring of the key's soft edge added."""
        n, du, dv, _ = self._taps(u, v, sources)
        low, ring = self._target(n, du, dv, sources, self._spaces[0])
        return np.where(low > NONE, low, ring)

    def _plan(self, u: float, v: float, exclude: tuple[str, ...], ws: _Workspace) -> _Plan:
        t0 = time.perf_counter()
        sources = self.nearest(u, v, exclude)
        if not sources:
            raise ValueError("no source cameras left")
        n, du, dv, closeness = self._taps(u, v, sources)
        low, ring = self._target(n, du, dv, sources, ws)
        return _Plan(sources, n, du, dv, closeness, low, ring, (time.perf_counter() - t0) * 1e3)

    # ---- steps 2 and 3: sample and blend --------------------------------------------------------------
    def _shade(self, p: _Plan, out: U8, start: int = 0, step: int = 1) -> None:
        texs = self._padded([s.texture for s in p.sources])
        disps = self._padded([s.disparity for s in p.sources])
        kernels.shade(
            p.low, p.ring, texs, disps, p.n, p.du, p.dv, p.closeness, 1.0 / self.agree_px, _packed(out), start, step
        )

    @staticmethod
    def _others() -> ThreadPoolExecutor:
        """The process's render threads beside the caller's (a second eye, or a view's other rows): one pool
        for every renderer, so that a take rendered frame by frame does not start threads per frame."""
        with _POOL_LOCK:
            if not _POOL:
                _POOL.append(ThreadPoolExecutor(max_workers=max(1, _cores() - 1), thread_name_prefix="render"))
            return _POOL[0]

    def _eye(self, u: float, v: float, exclude: tuple[str, ...], ws: _Workspace) -> Rendered:
        """A view on the calling thread alone: its target, then its shade."""
        return self._view(self._plan(u, v, exclude, ws), 1)

    def render(self, u: float, v: float, exclude: tuple[str, ...] = ()) -> Rendered:
        """The view at (u, v) (horizontal spacings, relative to the grid's origin) from the ``taps`` nearest
        sources not in ``exclude``: its target on this thread, its shade in interleaved block rows on all."""
        return self._view(self._plan(u, v, exclude, self._spaces[0]), self.threads)

    def _view(self, p: _Plan, k: int) -> Rendered:
        """The shaded view of a plan, its block rows interleaved over ``k`` threads (this one and k - 1 of the
        pool)."""
        t0 = time.perf_counter()
        out = np.empty((*self.shape, 4), np.uint8)
        rest = [self._others().submit(self._shade, p, out, i, k) for i in range(1, k)]
        self._shade(p, out, 0, k)
        for f in rest:
            f.result()
        return Rendered(out, p.low, [s.name for s in p.sources], p.target_ms, (time.perf_counter() - t0) * 1e3)

    def render_pair(
        self, left: tuple[float, float], right: tuple[float, float], exclude: tuple[str, ...] = ()
    ) -> tuple[Rendered, Rendered]:
        """Two views (an eye pair), each rendered whole on its own thread (every pass is serial and releases
        the GIL): on two cores, the pair takes about one view's time."""
        if self.threads < 2:
            return self._eye(*left, exclude, self._spaces[0]), self._eye(*right, exclude, self._spaces[1])
        second = self._others().submit(self._eye, *right, exclude, self._spaces[1])
        first = self._eye(*left, exclude, self._spaces[0])
        return first, second.result()


@dataclass
class _Plan:
    """A view's sources, their offsets and weights, and its target disparity (and ring): what step 1 makes
    and steps 2-3 read."""

    sources: list[Source]
    n: int
    du: F32
    dv: F32
    closeness: F32
    low: F32
    ring: F32
    target_ms: float


class _Workspace:
    """The half-resolution scratch images of one view's target, kept from view to view (fresh ones cost page
    faults: about as much as the passes that fill them)."""

    def __init__(self, hl: int, wl: int) -> None:
        self.dilated = np.empty((hl, wl), np.float32)
        self.closed = np.empty((hl, wl), np.float32)
        self.ring = np.empty((hl, wl), np.float32)
        self.last = np.empty(wl, np.int64)


def _cores() -> int:
    """The cores this process may run on."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
