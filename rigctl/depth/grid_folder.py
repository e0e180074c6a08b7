"""Grid folders (``r{row}c{col}.png`` + ``grid.yaml``, optional ``truth/<camera>.pfm``) read as a
:class:`~rigctl.depth.grid.Grid`: any rectified camera grid, so that external data can be processed and
checked. Every number of ``grid.yaml`` is held to sense (finite, within a float's reach for the depths made
from it, a focal length a picture of that width can have) and every picture header to the size budget before
any picture is decoded."""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Any, TypeGuard

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.depth.grid import F32, Grid, grid_from_arrays, read_truths
from rigctl.errors import RigFileError
from rigctl.imagefile import MAX_SIDE, png_size, read_png
from rigctl.layout import SAFE_CAMERA, grid_name, misspelt
from rigctl.rig import FOCAL_RANGE_WIDTHS
from rigctl.yamlfile import load_yaml_with_lines, refuse_unknown_keys

log = logging.getLogger(__name__)

GRID_SPACING = (1e-6, 1e6)  # spacing_x, spacing_y, in grid.yaml's own unit
MAX_GRID_PIXELS = 1 << 28  # all pictures of a grid folder together (nine UHD pictures are 75 million)
GRID_KEYS = ("spacing_x", "spacing_y", "focal_px", "doffs", "disparity_range_px")  # what grid.yaml may hold


def _png_picture(img: NDArray[Any]) -> NDArray[Any]:
    """A PNG as read by OpenCV: 8-bit kept as BGR bytes, 16-bit as float RGB in [0, 1]."""
    if img.dtype == np.uint8:
        if img.ndim == 2:
            return np.asarray(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR), np.uint8)
        return np.ascontiguousarray(img[..., :3])
    rgb = img.astype(np.float32) / np.float32(65535.0 if img.dtype == np.uint16 else 255.0)
    return rgb[..., 2::-1] if rgb.ndim == 3 else rgb  # BGR(A) to RGB: alpha, when there is one, left out


def load_grid_folder(folder: Path) -> Grid:
    path = folder / "grid.yaml"
    spec, lines = load_yaml_with_lines(path)
    if not isinstance(spec, dict):
        raise RigFileError(f"{path}: expected spacing_x, spacing_y, focal_px")
    refuse_unknown_keys(path, spec, GRID_KEYS, lines)  # a misspelt key is not silently left out, as in a rig file
    for key in ("spacing_x", "focal_px"):
        if key not in spec:
            raise RigFileError(f"{path}: {key} is required")
    for key in ("focal_px", "spacing_x", "spacing_y", "doffs"):
        v = spec.get(key)
        if v is None and key in ("spacing_y", "doffs"):
            continue
        if not _finite(v):
            raise RigFileError(f"{path}: {key}: must be a finite number, got {v!r:.60}")
        if (key in ("focal_px", "spacing_x") and v <= 0) or (key == "spacing_y" and v < 0):
            raise RigFileError(f"{path}: {key}: must be positive, got {v!r}")
        # beyond these, depth = focal_px * spacing / (disparity + doffs) is 0 or infinite in float32 everywhere
        if key.startswith("spacing") and v and not GRID_SPACING[0] <= v <= GRID_SPACING[1]:
            raise RigFileError(f"{path}: {key}: must be between {GRID_SPACING[0]:g} and {GRID_SPACING[1]:g}, got {v!r}")
        if key == "doffs" and abs(v) > MAX_SIDE:
            raise RigFileError(f"{path}: doffs: must be within +-{MAX_SIDE} px, got {v!r}")
    rng = _disparity_range(path, spec.get("disparity_range_px"))
    files = _grid_files(folder)
    sizes = {p: png_size(p) for p in files}  # every header within the budget before any picture is decoded
    total = sum(w * h for w, h in sizes.values())
    if total > MAX_GRID_PIXELS:
        raise RigFileError(f"{folder}: {len(files)} images of {total:,} pixels together: over {MAX_GRID_PIXELS:,}")
    width = sizes[files[0]][0]
    lo, hi = FOCAL_RANGE_WIDTHS  # the sense a calibration is held to
    if not lo * width <= spec["focal_px"] <= hi * width:
        raise RigFileError(
            f"{path}: focal_px: {spec['focal_px']!r} is not plausible for pictures {width} px wide "
            f"(expected {lo * width:g} to {hi * width:g} px)"
        )
    rows = {int(m[1]) for p in files if (m := SAFE_CAMERA.fullmatch(p.stem))}
    if spec.get("spacing_y") == 0 and len(rows) > 1:
        raise RigFileError(f"{path}: spacing_y: 0 puts the {len(rows)} rows of cameras at one place")
    ratio = float(spec.get("spacing_y") or spec["spacing_x"]) / float(spec["spacing_x"])
    _refuse_apart(files, sizes[files[0]], ratio, rng)
    images = {p.stem: read_png(p) for p in files}
    first = next(iter(images))
    for n, img in images.items():
        if img.shape[:2] != images[first].shape[:2]:
            h, w = img.shape[:2]
            h0, w0 = images[first].shape[:2]
            raise RigFileError(f"{folder / (n + '.png')}: image is {w}x{h}, but {first}.png is {w0}x{h0}: sizes differ")
    grid = grid_from_arrays(
        {n: _png_picture(img) for n, img in images.items()},
        float(spec["focal_px"]),
        float(spec["spacing_x"]),
        float(spec.get("spacing_y") or spec["spacing_x"]),
        float(spec.get("doffs") or 0.0),
        rng,
    )
    grid.truth = _folder_truth(folder / "truth", grid)
    return grid


def _grid_files(folder: Path) -> list[Path]:
    """The folder's pictures ``r{row}c{col}.png``, one per grid position and named as the position is written
    (no leading zeros: ``r01c0.png`` beside ``r1c0.png`` read as two cameras at one place). A name that is no
    grid position is left out with a warning."""
    files = sorted(p for p in folder.glob("r*c*.png") if grid_name(p.stem))
    for p in sorted(set(folder.glob("r*c*.png")) - set(files))[:8]:
        log.warning("%s: not named r{row}c{col}.png: left out of the grid", p)
    if not files:
        raise RigFileError(f"{folder}: no r{{row}}c{{col}}.png images")
    by_position: dict[str, list[Path]] = {}
    for p in files:
        by_position.setdefault(str(grid_name(p.stem)), []).append(p)
    for camera, named in by_position.items():
        if len(named) > 1:
            raise RigFileError(
                f"{' and '.join(str(p) for p in named)}: {len(named)} pictures of camera {camera} (a grid position "
                f"is written without leading zeros: keep {camera}.png alone)"
            )
        if wrong := misspelt(named[0].stem):  # r01c0.png, r٢c1.png
            raise RigFileError(f"{named[0]}: grid position {wrong}.png")
    return files


def _refuse_apart(files: list[Path], size: tuple[int, int], ratio: float, rng: tuple[float, float] | None) -> None:
    """Refuse cameras that do not form one grid: between cameras (dx, dy) horizontal spacings apart a point of
    disparity d moves (d dx, d dy) px, so past ``w / |dx|`` (or ``h / |dy|``) it lies outside the other's picture.
    Two cameras share a view when that does not happen at 1 px (or at the planned range's largest disparity,
    when smaller), and every camera must reach every other through cameras that share views. A camera alone
    was matched against nothing its depth could come from (a misnamed ``r9999c9999.png`` beside a 3x3 set was
    estimated from disparities under 0.01 px, exit 0): it is named with its nearest camera. Two grids far apart
    in one folder (r0c0..r2c2 and r100c100..r102c102) were each estimated as if the other were not there, with
    one range and one report, exit 0: the groups are named. ``ratio`` is spacing_y / spacing_x."""
    if len(files) < 2:
        return
    w, h = size
    probe = min(1.0, max(abs(rng[0]), abs(rng[1]))) if rng else 1.0
    # positions scaled so that two cameras share a view when both coordinates differ by under 1: the cameras of
    # one unit cell all share views, and cells are joined through the 8 around them (linear in the cameras)
    pos = {p: (col * probe / w, row * ratio * probe / h) for p in files for row, col in [_position(p)]}
    cells: dict[tuple[int, int], list[Path]] = {}
    for p, (x, y) in pos.items():
        cells.setdefault((math.floor(x), math.floor(y)), []).append(p)
    at = {c: np.array([pos[p] for p in here]) for c, here in cells.items()}
    root = {c: c for c in cells}

    def find(c: tuple[int, int]) -> tuple[int, int]:
        while root[c] != c:
            root[c] = root[root[c]]
            c = root[c]
        return c

    for (cx, cy), a in at.items():
        for i, j in ((1, -1), (1, 0), (1, 1), (0, 1)):
            b = at.get((cx + i, cy + j))
            if b is not None and _share_a_view(a, b, i, j):
                root[find((cx + i, cy + j))] = find((cx, cy))
    groups: dict[tuple[int, int], list[Path]] = {}
    for c, here in cells.items():
        groups.setdefault(find(c), []).extend(here)
    if len(groups) == 1:
        return
    alone = [g[0] for g in groups.values() if len(g) == 1]
    if alone:
        raise _isolated(min(alone), pos, (w / probe, h / probe), probe, size)
    named = sorted((sorted(g, key=_position) for g in groups.values()), key=lambda g: _position(g[0]))
    said = " and ".join(f"{g[0].stem}..{g[-1].stem} ({len(g)} cameras)" for g in named[:2])
    more = f" (and {len(named) - 2} more)" if len(named) > 2 else ""
    raise RigFileError(
        f"{files[0].parent}: the pictures form {len(named)} grids that share no view: {said}{more}: a point of "
        f"{probe:g} px disparity moves out of the {w}x{h} picture between them (two grids in one folder?)"
    )


def _share_a_view(a: NDArray[np.float64], b: NDArray[np.float64], i: int, j: int) -> bool:
    """Whether a camera of cell ``a`` and one of cell ``b`` (``i``, ``j`` cells from it) differ by under 1 in both
    coordinates: along an axis where the cells differ by ``s`` = +-1, s a > s b - 1; along one where they do not,
    always. A dominance query, in n log n: some point of ``a`` above some point of ``b`` in both."""
    au, bu = (i * a[:, 0], i * b[:, 0] - 1) if i else (np.ones(len(a)), np.zeros(len(b)))
    av, bv = (j * a[:, 1], j * b[:, 1] - 1) if j else (np.ones(len(a)), np.zeros(len(b)))
    order = np.argsort(au)
    u, top = au[order], np.maximum.accumulate(av[order][::-1])[::-1]  # the largest v among a's from there on
    k = np.searchsorted(u, bu, side="right")  # the first a with u above b's
    inside = k < len(u)
    return bool(np.any(top[k[inside]] > bv[inside]))


def _position(p: Path) -> tuple[int, int]:
    m = SAFE_CAMERA.fullmatch(p.stem)
    assert m is not None
    return int(m[1]), int(m[2])


def _isolated(
    p: Path, pos: dict[Path, tuple[float, float]], unit: tuple[float, float], probe: float, size: tuple[int, int]
) -> RigFileError:
    """The refusal of camera ``p``, which shares no view: naming its nearest camera and how far it is."""
    x, y = pos[p]

    def apart(q: Path) -> tuple[float, float]:
        return abs(pos[q][0] - x), abs(pos[q][1] - y)

    near = min((q for q in pos if q != p), key=lambda q: (max(apart(q)), sum(apart(q))))
    dx, dy = apart(near)
    return RigFileError(
        f"{p}: shares no view with any other camera: the nearest, {near.name}, is {dx * unit[0]:g} across and "
        f"{dy * unit[1]:g} down (in spacing_x), so a point of {probe:g} px disparity moves out of the "
        f"{size[0]}x{size[1]} picture between them (a misnamed picture?)"
    )


def _folder_truth(folder: Path, grid: Grid) -> dict[str, F32] | None:
    """A grid folder's reference disparities, ``truth/<camera>.pfm`` (e.g. the depth MIV content came
    with, ``rigctl miv import``): what depth scores its estimates against. None when there are none. A
    ``truth`` that is there but no folder, or a camera's PFM that is there but no regular file, is refused."""
    if not os.path.lexists(folder):
        return None
    if not folder.is_dir():
        raise RigFileError(f"{folder}: reference disparities: expected a folder of <camera>.pfm: refused")
    return read_truths(folder, grid.names, grid.shape) or None


def _disparity_range(path: Path, rng: object) -> tuple[float, float] | None:
    """``disparity_range_px: [min, max]``: two finite numbers, min below max, within a picture's width."""
    if rng is None:
        return None
    ok = isinstance(rng, list) and len(rng) == 2 and all(_finite(v) for v in rng)
    if not ok or not (-MAX_SIDE <= rng[0] < rng[1] <= MAX_SIDE):  # type: ignore[index]
        raise RigFileError(
            f"{path}: disparity_range_px: expected [min, max], two numbers with min < max within "
            f"+-{MAX_SIDE} px, got {rng!r:.60}"
        )
    return float(rng[0]), float(rng[1])  # type: ignore[index]


def _finite(v: object) -> TypeGuard[int | float]:
    """A YAML number (not a boolean) that is finite as a float: an integer of 400 digits is not (math.isfinite
    raised OverflowError on it, a traceback)."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return False
    try:
        return math.isfinite(v)
    except OverflowError:
        return False
