"""Stratified light-field scenes with exact disparity truth, as 3x3 grids (and grid folders).

What real light fields have and the simulated presenter lacks: slanted and curved surfaces, texture at
several scales, thin structures, low-contrast regions, and a true disparity that is fractional everywhere.
Each scene is a stack of textured layers given in the reference camera's coordinates: a layer has a
disparity function D(X, Y), a texture and a support. Camera b, at (rx, ry) spacings from the reference, sees
the layer point (X, Y) at (X - D rx, Y - D ry); each of its pixels solves that for (X, Y) by fixed-point
iteration, and the nearest (largest D) layer that covers it wins. Rendered at 3x and area-averaged (a pixel
integrates light), with sensor noise and 8-bit quantisation. The truth is D of the visible layer at the
reference camera's pixel centres, exact by construction.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray

from rigctl.depth.grid import Grid, grid_from_arrays
from rigctl.pfm import write_pfm
from rigctl.publish import publish_png

F32 = NDArray[np.float32]
Field = Callable[[F32, F32], F32]
log = logging.getLogger(__name__)

SUPER = 3  # supersampling factor of the renderer
SPACING = (3.0, 2.0)  # the rig's 120 x 78 mm as light-field view steps: vertical disparity is 2/3 of horizontal


@dataclass
class Layer:
    disparity: Field  # D(X, Y), px of the horizontal spacing
    texture: F32  # RGB texture, sampled at (X, Y) * TEX + margin
    support: Field | None = None  # > 0 where the layer exists (None: everywhere)


TEX = 2  # texture images hold 2 samples per reference pixel (interpolated smoothly between)


def texture(
    rng: np.random.Generator, size: tuple[int, int], scales: list[tuple[float, float]], grey: float = 0.5
) -> F32:
    """Band-limited noise: the sum of Gaussian-blurred white noise at (sigma px, amplitude) pairs."""
    h, w = size[0] * TEX, size[1] * TEX
    out = np.full((h, w, 3), grey, np.float32)
    tint = rng.uniform(0.7, 1.3, 3).astype(np.float32)
    for sigma, amp in scales:
        n = rng.standard_normal((h, w)).astype(np.float32)
        n = np.asarray(cv2.GaussianBlur(n, (0, 0), sigma * TEX), np.float32)
        n *= amp / max(float(n.std()), 1e-6)
        out += n[..., None] * tint[None, None]
    return np.clip(out, 0.0, 1.0)


def render(layers: list[Layer], size: tuple[int, int], rel: tuple[float, float], margin: int) -> F32:
    """One camera at ``rel`` spacings from the reference (3x supersampled, area averaged)."""
    h, w = size
    ys, xs = np.mgrid[0 : h * SUPER, 0 : w * SUPER].astype(np.float32)
    u, v = (xs + 0.5) / SUPER - 0.5, (ys + 0.5) / SUPER - 0.5
    best_d = np.full(u.shape, -np.inf, np.float32)
    img = np.zeros((*u.shape, 3), np.float32)
    for layer in layers:
        x, y = u.copy(), v.copy()
        for _ in range(12):  # X = u + D(X, Y) rx converges while |dD/dX rx| < 1
            d = layer.disparity(x, y)
            x, y = u + d * np.float32(rel[0]), v + d * np.float32(rel[1])
        d = layer.disparity(x, y)
        cover = np.ones(u.shape, bool) if layer.support is None else layer.support(x, y) > 0
        near = cover & (d > best_d)
        mx, my = (x + margin) * TEX, (y + margin) * TEX
        tex = cv2.remap(layer.texture, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
        img[near] = tex[near]
        best_d = np.where(near, d, best_d)
    return np.asarray(cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA), np.float32)


def truth_of(layers: list[Layer], size: tuple[int, int]) -> F32:
    h, w = size
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    best = np.full((h, w), -np.inf, np.float32)
    for layer in layers:
        d = layer.disparity(x, y)
        cover = np.ones((h, w), bool) if layer.support is None else layer.support(x, y) > 0
        best = np.where(cover & (d > best), d, best)
    return best


def _grid(layers: list[Layer], size: tuple[int, int], seed: int, margin: int, noise: float) -> Grid:
    rng = np.random.default_rng(seed + 1000)
    images = {}
    ratio = SPACING[1] / SPACING[0]
    for r in range(3):
        for c in range(3):
            img = render(layers, size, (c - 1.0, (r - 1.0) * ratio), margin)
            img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
            images[f"r{r}c{c}"] = np.round(np.clip(img, 0, 1) * 255) / 255  # 8-bit, as light fields ship
    truth = truth_of(layers, size)
    lo, hi = float(truth.min()), float(truth.max())
    grid = grid_from_arrays(images, 1000.0, SPACING[0], SPACING[1], 0.0, (np.floor(lo) - 2, np.ceil(hi) + 2))
    grid.truth = {"r1c1": truth}
    return grid


def surfaces(size: tuple[int, int] = (256, 256), seed: int = 0) -> Grid:
    """A slanted, textured background; a curved (paraboloid) cap; a slanted box whose face is weakly textured."""
    h, w = size
    rng = np.random.default_rng(seed)
    m = 32
    tsize = (h + 2 * m, w + 2 * m)
    cx, cy, rad = 0.62 * w, 0.42 * h, 0.22 * min(h, w)

    def back(x: F32, y: F32) -> F32:
        return np.asarray(-2.3 + 0.011 * x + 0.006 * y, np.float32)

    def cap(x: F32, y: F32) -> F32:
        r2 = ((x - cx) ** 2 + (y - cy) ** 2) / rad**2
        return np.asarray(3.1 + 2.4 * np.maximum(1.0 - r2, 0.0), np.float32)

    def cap_support(x: F32, y: F32) -> F32:
        return np.asarray(rad**2 - (x - cx) ** 2 - (y - cy) ** 2, np.float32)

    def box(x: F32, y: F32) -> F32:
        return np.asarray(1.37 - 0.017 * (x - 0.25 * w) + 0.009 * (y - 0.7 * h), np.float32)

    def box_support(x: F32, y: F32) -> F32:
        return np.asarray(
            np.minimum(np.minimum(x - 0.08 * w, 0.42 * w - x), np.minimum(y - 0.55 * h, 0.92 * h - y)), np.float32
        )

    layers = [
        Layer(back, texture(rng, tsize, [(0.6, 0.08), (2.0, 0.12), (8.0, 0.15)])),
        Layer(cap, texture(rng, tsize, [(1.0, 0.10), (4.0, 0.15)], 0.6), cap_support),
        Layer(box, texture(rng, tsize, [(0.8, 0.015), (3.0, 0.02)], 0.45), box_support),  # low contrast
    ]
    return _grid(layers, size, seed, m, 0.6 / 255)


def thin(size: tuple[int, int] = (256, 256), seed: int = 0) -> Grid:
    """Thin bars (1.5 to 4 px wide, upright and diagonal) in front of a curved, finely textured wall."""
    h, w = size
    rng = np.random.default_rng(seed + 7)
    m = 32
    tsize = (h + 2 * m, w + 2 * m)

    def wall(x: F32, y: F32) -> F32:
        return np.asarray(-1.6 + 1.2 * np.sin(x / w * 3.1) + 0.004 * y, np.float32)

    layers = [Layer(wall, texture(rng, tsize, [(0.5, 0.10), (1.5, 0.10), (5.0, 0.12)]))]
    for i, (width, slope, d) in enumerate([(1.5, 0.0, 4.3), (2.5, 0.35, 3.7), (4.0, -0.5, 5.2), (3.0, 0.0, 2.9)]):
        x_at = (0.15 + 0.22 * i) * w

        def bar(x: F32, y: F32, x_at: float = x_at, slope: float = slope, width: float = width) -> F32:
            return np.asarray(width / 2 - np.abs(x - (x_at + slope * (y - h / 2))), np.float32)

        def bar_d(x: F32, y: F32, d: float = d) -> F32:
            return np.asarray(d + 0.003 * (y - h / 2), np.float32)

        layers.append(Layer(bar_d, texture(rng, tsize, [(0.8, 0.12), (3.0, 0.1)], 0.8), bar))
    return _grid(layers, size, seed, m, 0.6 / 255)


def step(
    size: tuple[int, int] = (240, 320),
    far: float = 6.0,
    near: float | None = 18.0,
    square: tuple[int, int, int] = (80, 110, 80),
    seed: int = 0,
) -> Grid:
    """A fronto-parallel textured plane at disparity ``far`` and, unless ``near`` is None, a textured square
    at ``near`` in front of it: ``square`` = (top, left, side) in the reference camera's pixels (its support
    covers the pixel centres top..top + side - 1, left..left + side - 1). Every other camera sees bands of
    the plane next to the square hidden, (near - far) times its baseline wide."""
    rng = np.random.default_rng(seed + 11)
    m = 32
    tsize = (size[0] + 2 * m, size[1] + 2 * m)
    top, left, side = square

    def plane(x: F32, y: F32) -> F32:
        return np.full(np.shape(x), far, np.float32)

    def front(x: F32, y: F32) -> F32:
        return np.full(np.shape(x), near, np.float32)

    def inside(x: F32, y: F32) -> F32:
        lo_x, lo_y = left - 0.5, top - 0.5
        return np.asarray(
            np.minimum(np.minimum(x - lo_x, lo_x + side - x), np.minimum(y - lo_y, lo_y + side - y)), np.float32
        )

    layers = [Layer(plane, texture(rng, tsize, [(0.7, 0.10), (2.5, 0.12), (8.0, 0.12)]))]
    if near is not None:
        layers.append(Layer(front, texture(rng, tsize, [(0.8, 0.12), (3.0, 0.12)], 0.6), inside))
    return _grid(layers, size, seed, m, 0.6 / 255)


SCENES: dict[str, Callable[..., Grid]] = {"surfaces": surfaces, "thin": thin}


def write_grid_folder(grid: Grid, folder: Path) -> Path:
    """The grid as a grid folder (r{row}c{col}.png + grid.yaml), with the truth as truth/<camera>.pfm."""
    folder.mkdir(parents=True, exist_ok=True)
    for n in grid.names:
        publish_png(folder / f"{n}.png", grid.bgr8(n))
    spacing_y = min((abs(o[1]) for o in grid.offsets.values() if abs(o[1]) > 1e-6), default=1.0) * grid.spacing
    spec: dict[str, object] = {
        "spacing_x": grid.spacing,
        "spacing_y": float(spacing_y),
        "focal_px": grid.focal_px,
        "doffs": grid.doffs,
    }
    if grid.disparity_range is not None:
        spec["disparity_range_px"] = [float(v) for v in grid.disparity_range]
    (folder / "grid.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    for n, t in (grid.truth or {}).items():
        (folder / "truth").mkdir(exist_ok=True)
        write_pfm(folder / "truth" / f"{n}.pfm", t)
    return folder


def shifted(grid: Grid, ref: str, s: float, room: float | None = None) -> Grid:
    """The grid as parallel cameras would see it with every disparity grown by ``s`` px per horizontal
    spacing: each view is cropped ``s`` times its offset from ``ref`` further along (what a sensor shift
    undoes). ``room`` (>= s, default s) fixes the reference camera's crop, so grids shifted by different
    amounts share the same reference picture. Crops must be whole pixels (s times every offset); the truth
    and the disparity range are shifted with the views."""
    room = s if room is None else room
    if room < s or s < 0:
        raise ValueError(f"shift {s} needs room >= shift >= 0, got room {room}")
    h, w = grid.shape
    ox = [o[0] for o in grid.offsets.values()]
    oy = [o[1] for o in grid.offsets.values()]
    rx, ry = grid.offsets[ref]
    span_x, span_y = round(room * (max(ox) - min(ox))), round(room * (max(oy) - min(oy)))
    if span_x >= w or span_y >= h:
        raise ValueError(f"a shift of {room} px per spacing leaves nothing of a {w}x{h} grid")
    images = {}
    for n, (nx, ny) in grid.offsets.items():
        cx = room * (rx - min(ox)) + s * (nx - rx)
        cy = room * (ry - min(oy)) + s * (ny - ry)
        if abs(cx - round(cx)) > 1e-6 or abs(cy - round(cy)) > 1e-6:
            raise ValueError(f"shift {s} moves camera {n} by a fraction of a pixel ({cx}, {cy})")
        x0, y0 = round(cx), round(cy)
        images[n] = grid.images[n][y0 : y0 + h - span_y, x0 : x0 + w - span_x]
    out = Grid(list(grid.names), images, dict(grid.offsets), grid.focal_px, grid.spacing, grid.doffs)
    if grid.disparity_range is not None:
        out.disparity_range = (grid.disparity_range[0] + s, grid.disparity_range[1] + s)
    if grid.truth and ref in grid.truth:
        x0, y0 = round(room * (rx - min(ox))), round(room * (ry - min(oy)))
        out.truth = {ref: grid.truth[ref][y0 : y0 + h - span_y, x0 : x0 + w - span_x] + np.float32(s)}
    return out


def seen_by_all(grid: Grid, ref: str, disparity: F32, margin: int = 0) -> NDArray[np.bool_]:
    """Pixels of ``ref`` whose point at ``disparity`` lies inside every view's frame (``margin`` px in)."""
    h, w = disparity.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    ok = np.isfinite(disparity)
    d = np.where(ok, disparity, 0).astype(np.float32)
    rx0, ry0 = grid.offsets[ref]
    for nx, ny in grid.offsets.values():
        x, y = xs - d * np.float32(nx - rx0), ys - d * np.float32(ny - ry0)
        ok &= (x >= margin) & (x <= w - 1 - margin) & (y >= margin) & (y <= h - 1 - margin)
    return np.asarray(ok)
