"""Depth of one camera of a rectified grid from every other camera, each with its own baseline
(multi-baseline matching): key the subject, search only its bounding box, run the preset's engine (the cost
volume, the plane sweep or the fused pairs: ``presets.py``), then mark what the estimate cannot vouch for
(no view, textureless or saturated, at the planned range's edge) and give a 0..1 confidence. ``cross_check``
compares two cameras' results."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.cost import F32, TRUNCATE
from rigctl.depth.edge import DEPTH_COVERAGE, coverage, sensor_fixed
from rigctl.depth.grid import Grid
from rigctl.depth.packed import BitPlane, FillPlane, PackedField, PackedPlane
from rigctl.depth.pair_fusion import pairs_engine
from rigctl.depth.presets import Preset
from rigctl.depth.search import EstimateStats, SearchJob
from rigctl.depth.sweep import sweep_engine
from rigctl.depth.volume_engine import volume_engine
from rigctl.errors import ParameterError
from rigctl.keying import Keyer, subject_box

DEFAULT_KEYER = Keyer()


@dataclass
class DepthResult:
    # every plane held packed until the write (``packed.py``: most of a presenter's frame is the screen's one
    # value): each read makes a new read-only plane, so change one by assigning it (descriptors, the fields'
    # storage: no default shared between results). About 3 bytes a pixel with the screen two thirds of the
    # frame, not 15
    # +inf where there is no estimate (keyed background, outside every view)
    disparity: PackedField[F32] = PackedField(FillPlane.filling(np.inf))  # noqa: RUF009
    confidence: PackedField[F32] = PackedField(FillPlane.filling(0.0))  # noqa: RUF009  # 0..1
    # textureless or saturated: an estimate, not to be trusted
    unreliable: PackedField[NDArray[np.bool_]] = PackedField(BitPlane.of)  # noqa: RUF009
    # the best match lay at the edge of the planned range
    bound_hit: PackedField[NDArray[np.bool_]] = PackedField(BitPlane.of)  # noqa: RUF009
    matte: PackedField[F32] = PackedField(PackedPlane.of)  # noqa: RUF009  # the keyer's
    # no match found: filled from the background side (default: none)
    filled: PackedField[NDArray[np.bool_]] = PackedField(BitPlane.of, empty=lambda: np.zeros((0, 0), bool))  # noqa: RUF009
    stats: EstimateStats = field(default_factory=lambda: EstimateStats())
    # the keyer whose matte of the camera's picture ``matte`` is (the export's soft key starts from it rather
    # than keying the picture again); None when the caller gave the matte or nothing was keyed
    keyed_by: Keyer | None = None

    def keyed_a_screen(self) -> bool:
        """Whether the matte is below 1 anywhere (a screen was keyed), without making the plane."""
        held = PackedField.held(self, "matte")
        return held.any_below_one() if isinstance(held, PackedPlane) else bool((held.plane() < 1).any())


def choose_views(grid: Grid, ref: str, mode: str) -> list[str]:
    ox, oy = grid.offsets[ref]
    others = [n for n in grid.names if n != ref]
    if mode == "all":
        return others
    # grid steps: the smallest offsets that are a real step, not a camera mounted a fraction of a mm off
    steps = [abs(grid.offsets[n][0] - ox) for n in others if abs(grid.offsets[n][0] - ox) > 0.2]
    sx = min(steps) if steps else 1.0
    vsteps = [abs(grid.offsets[n][1] - oy) for n in others if abs(grid.offsets[n][1] - oy) > 0.2]
    sy = min(vsteps) if vsteps else 1.0
    out = []
    for n in others:
        dx, dy = (grid.offsets[n][0] - ox) / sx, (grid.offsets[n][1] - oy) / sy
        if (mode == "horizontal" and abs(dy) < 0.25 and abs(abs(dx) - 1) < 0.25) or (
            mode == "neighbours" and max(abs(dx), abs(dy)) < 1.25
        ):
            out.append(n)
    return out or others


def seen_range(grid: Grid, ref: str, views: list[str], lo: float, hi: float) -> tuple[float, float]:
    """``lo..hi`` clipped to the disparities some view can still see: past ``max`` over the views of
    ``min(w / |dx|, h / |dy|)`` a point of the reference lands outside every view's picture, whatever its
    position, so a range planned from an absurd distance (``--near 1e-300``) costs no more than the picture.
    Empty (``hi < lo``) when the whole range lies beyond."""
    h, w = grid.shape
    ox, oy = grid.offsets[ref]
    reach = 0.0
    for n in views:
        dx, dy = abs(grid.offsets[n][0] - ox), abs(grid.offsets[n][1] - oy)
        reach = max(reach, min(w / dx if dx > 1e-9 else math.inf, h / dy if dy > 1e-9 else math.inf))
    return max(lo, -reach), min(hi, reach)


def estimate(
    grid: Grid,
    ref: str,
    d_range: tuple[float, float],
    preset: Preset,
    keyer: Keyer | None = DEFAULT_KEYER,
    matte: F32 | None = None,
) -> DepthResult:
    """Disparity of camera ``ref``. ``keyer`` None: no keying (every pixel is searched)."""
    t_start = time.perf_counter()
    if ref not in grid.images:
        raise ParameterError(f"camera {ref} is not in the grid (it has {', '.join(grid.names)})")
    lo, hi = float(d_range[0]), float(d_range[1])
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
        raise ParameterError(f"disparity range must be finite with min <= max, got {d_range}")
    h, w = grid.shape
    stats = EstimateStats(camera=ref, preset=preset.name)
    t0 = time.perf_counter()
    keyed_by = keyer if matte is None else None
    if matte is None:
        matte = keyer.matte(grid.images[ref]) if keyer is not None else np.ones((h, w), np.float32)
    # depth where the subject covers at least half the pixel (``edge.py``): not on the screen beside it
    fg = coverage(grid.images[ref], matte) >= DEPTH_COVERAGE
    grid.frames.forget_last()  # the search reads the greys; the picture is made again if asked
    key = PackedPlane.of(matte)  # what the result holds (``packed.py``); the plane is not needed again here
    del matte
    stats["key_s"] = time.perf_counter() - t0
    stats["keyed_background_share"] = float(1.0 - fg.mean())
    views = choose_views(grid, ref, preset.views)
    moving = [
        n
        for n in views
        if max(abs(grid.offsets[n][0] - grid.offsets[ref][0]), abs(grid.offsets[n][1] - grid.offsets[ref][1])) > 1e-9
    ]
    stats["views"] = moving
    lo, hi = seen_range(grid, ref, moving, lo, hi)
    nothing = {
        "every pixel keyed as background": not fg.any(),
        "no camera at a different position": not moving,
        f"the range {d_range[0]:g}..{d_range[1]:g} px lies beyond every view's picture": hi < lo,
    }
    if any(nothing.values()):
        stats["note"] = next(why for why, so in nothing.items() if so)
        stats["seconds"] = time.perf_counter() - t_start
        return DepthResult(
            np.full((h, w), np.inf, np.float32),
            np.zeros((h, w), np.float32),
            np.zeros((h, w), bool),
            np.zeros((h, w), bool),
            key,
            np.zeros((h, w), bool),
            stats,
            keyed_by,
        )
    box = subject_box(fg, margin=preset.window)
    assert box is not None
    stats["searched_share"] = float((box[1] - box[0]) * (box[3] - box[2]) / (h * w))
    keep = max(1, math.ceil(preset.keep * len(moving)))

    y0, y1, x0, x1 = box
    job = SearchJob(grid, ref, moving, box, (lo, hi), keep, preset, stats, fg[y0:y1, x0:x1])
    if preset.engine == "volume":
        crop = volume_engine(job)
    else:
        crop = pairs_engine(job) if preset.engine == "pairs" else sweep_engine(job)
    disp = crop.disparity
    if preset.median:
        disp = np.asarray(cv2.medianBlur(np.ascontiguousarray(disp, dtype=np.float32), preset.median), np.float32)

    out = np.full((h, w), np.inf, np.float32)
    region = fg[y0:y1, x0:x1]
    valid = region & ~crop.no_view & np.isfinite(disp)
    out[y0:y1, x0:x1] = np.where(valid, disp, np.inf)
    t0 = time.perf_counter()
    fixed = _drop_sensor_fixed(grid, ref, moving, out, (lo, hi), keyer.min_area if keyer else DEFAULT_KEYER.min_area)
    valid &= ~fixed[y0:y1, x0:x1]
    stats["sensor_fixed_pixels"] = int(fixed.sum())
    stats["sensor_fixed_s"] = time.perf_counter() - t0
    conf = np.zeros((h, w), np.float32)
    c_local = np.clip(1.0 - crop.cost / TRUNCATE, 0, 1) * crop.distinct
    unreliable_local = (crop.texture < 0.01) | (crop.bright > 0.98)
    conf[y0:y1, x0:x1] = np.where(valid & ~unreliable_local, c_local, 0.0)
    unreliable = np.zeros((h, w), bool)
    unreliable[y0:y1, x0:x1] = valid & unreliable_local
    bound_hit = np.zeros((h, w), bool)
    # the match lies at the edge of the planned range: the truth may lie beyond it
    at_edge = (disp >= hi - 0.5) | (disp <= lo + 0.5)
    bound_hit[y0:y1, x0:x1] = valid & (crop.bound | at_edge)
    stats["seconds"] = time.perf_counter() - t_start
    stats["estimated_share_of_subject"] = float(valid.sum() / max(1, fg.sum()))
    stats["bound_hit_pixels"] = int(bound_hit.sum())
    stats["unreliable_pixels"] = int(unreliable.sum())
    filled = np.zeros((h, w), bool)
    if crop.filled is not None:
        filled[y0:y1, x0:x1] = valid & crop.filled
        stats["filled_from_background_pixels"] = int(filled.sum())
    return DepthResult(out, conf, unreliable, bound_hit, key, filled, stats, keyed_by)


def _drop_sensor_fixed(
    grid: Grid, ref: str, views: list[str], out: F32, d_range: tuple[float, float], min_area: float
) -> NDArray[np.bool_]:
    """Pixels fixed to the sensor (:func:`edge.sensor_fixed`) and the specks they leave (estimated blobs
    smaller than the keyer's ``min_area`` share of the image that touch them), set to no estimate in ``out``
    and returned."""
    fixed = sensor_fixed(grid, ref, views, out, d_range)
    if fixed.any():
        rest = np.isfinite(out) & ~fixed
        n, labels, stats, _ = cv2.connectedComponentsWithStats(rest.astype(np.uint8), connectivity=8)
        touching = np.unique(labels[cv2.dilate(fixed.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0])
        small = np.zeros(n, bool)
        small[touching] = stats[touching, cv2.CC_STAT_AREA] < min_area * out.size
        small[0] = False
        fixed |= small[labels]
        out[fixed] = np.inf
    return fixed


def cross_check(a: DepthResult, b: DepthResult, rel: tuple[float, float], tol: float = 1.0) -> NDArray[np.bool_]:
    """Pixels of ``a`` whose disparity disagrees with ``b``'s at the same point (b at offset ``rel`` from a)."""
    da, db = a.disparity, b.disparity  # each read makes the plane (held packed)
    h, w = da.shape
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
    d = np.where(np.isfinite(da), da, 0).astype(np.float32)
    mx, my = gx - d * np.float32(rel[0]), gy - d * np.float32(rel[1])
    db = np.where(np.isfinite(db), db, -1e6).astype(np.float32)
    seen = cv2.remap(db, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=-1e6)
    return np.asarray(np.isfinite(da) & (seen > -1e5) & (np.abs(seen - da) > tol))
