"""Issue 30: the report counts the pixels estimated from fewer than three views. Parallel cameras leave
bands that only some views see: at the frame's edges (a point beyond another camera's frame) and behind every
foreground edge (a nearer surface covers the point in another camera). On a textured square in front of a
textured plane, seen from a corner camera (the one whose views all lie on one side, so a band behind an edge
is hidden from most of them), the count must grow by the bands behind the square's edges, and a plane alone
must give only the frame's edges. The expected count is worked out here from the scene's geometry."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from rigctl.depth.estimate import estimate
from rigctl.depth.grid import Grid
from rigctl.depth.presets import PRESETS
from rigctl.depth.scenes import step

REF = "r0c0"
FAR, NEAR = 6.3, 18.3  # neither a whole pixel: no boundary falls on a pixel centre
TOP, LEFT, SIDE = 80, 110, 80  # the square in the centre camera's pixels (scenes.step)


def views_that_see(grid: Grid, near: float | None) -> NDArray[np.int64]:
    """Per pixel of REF: how many other cameras see its point, from the scene's geometry. Camera b at
    ``rel`` spacings from the centre camera sees a point X of a layer at disparity D at X - D rel; a point of
    the plane is hidden from a view r (from REF) when the square covers X + (near - far) r in REF's
    picture."""
    h, w = grid.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    cx, cy = grid.offsets["r1c1"]
    bx, by = grid.offsets[REF]

    def in_square(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.bool_]:
        # the square's support in REF's picture: the centre camera's, moved by near times REF's offset
        assert near is not None
        x0, y0 = LEFT - 0.5 - near * (bx - cx), TOP - 0.5 - near * (by - cy)
        return np.asarray((x >= x0) & (x < x0 + SIDE) & (y >= y0) & (y < y0 + SIDE))

    on_square = in_square(xs, ys) if near is not None else np.zeros((h, w), bool)
    d = np.where(on_square, near or 0.0, FAR)
    count = np.zeros((h, w), np.int64)
    for n, (ox, oy) in grid.offsets.items():
        if n == REF:
            continue
        rx, ry = ox - bx, oy - by
        mx, my = xs - d * rx, ys - d * ry
        seen = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
        if near is not None:
            seen &= on_square | ~in_square(xs + (near - FAR) * rx, ys + (near - FAR) * ry)
        count += seen
    return count


def counted(grid: Grid) -> int:
    assert grid.disparity_range is not None
    res = estimate(grid, REF, grid.disparity_range, PRESETS["best"], keyer=None)
    assert res.stats["engine"] == "cost volume"
    return res.stats["fewer_than_3_views_pixels"]


def test_the_count_of_pixels_seen_by_fewer_than_three_views_includes_the_bands_behind_a_foreground_edge() -> None:
    plane, scene = (
        step(far=FAR, near=None, square=(TOP, LEFT, SIDE)),
        step(far=FAR, near=NEAR, square=(TOP, LEFT, SIDE)),
    )
    h, w = scene.shape
    edges = int((views_that_see(plane, None) < 3).sum())
    with_square = int((views_that_see(scene, NEAR) < 3).sum())
    # the frame's edges: REF's views all lie right of and below it, so the columns within FAR px of the
    # left edge (6 of 8 views lose them) and the rows within 2/3 FAR px of the top are seen by two
    cols, rows = math.ceil(FAR), math.ceil(FAR * 2 / 3)
    assert edges == cols * h + rows * w - cols * rows
    # behind the square: a band of the plane hidden from the six views in the two columns right of REF, and
    # one hidden from the six in the two rows below it: (NEAR - FAR) times the nearest column's or row's
    # offset wide, along the part of the edge that even the furthest of the six has covered (the square moves
    # by (NEAR - FAR) times the other offset in it: up to 4/3 of a column step, up to 2 row steps)
    gap = NEAR - FAR
    assert with_square - edges == round(gap * (SIDE - 4 / 3 * gap) + 2 / 3 * gap * (SIDE - 2 * gap))
    got_plane, got_scene = counted(plane), counted(scene)
    # the estimate's edges may sit a pixel off the true ones: a frame edge's row or column, a band's length
    assert abs(got_plane - edges) <= 0.01 * edges, (got_plane, edges)
    assert abs(got_scene - with_square) <= (SIDE - 4 / 3 * gap) + (SIDE - 2 * gap), (got_scene, with_square)
