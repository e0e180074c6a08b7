"""Soft edges for the simulated array (``edges=soft``): each pixel on an edge is the mean of 4x4 rays spread
over its area (and, when the presenter moves, over the exposure time: motion blur), so a silhouette is
anti-aliased and a strand of hair thinner than a pixel covers a fraction of it, as a real sensor integrates
light. The same samples give the truth a matting benchmark needs: the share of the pixel the subject covers
(alpha) and the subject's own colour there, unmixed from the screen behind it (the mean of the samples that
hit the subject). Samples are added as light (scene-linear, through the inverse of BT.709's OETF) and the
sums encoded again, as a camera's pixel integrates light before its transfer function; the truth's colour is
in the picture's code values, like the picture.

Only the pixels that need it are supersampled: within two pixels of a change of the visible primitive in the
one-ray render, and all of every thin primitive's box (one ray per pixel may miss a strand altogether).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import NDArray
from rigctl.simulators.raycast import RayCamera, RenderResult, Scene, render

from rigctl.exr import bt709_to_linear, linear_to_bt709

if TYPE_CHECKING:
    from rigctl.simulators.array import SimArray

F32 = NDArray[np.float32]
SUB = 4  # SUB x SUB samples per edge pixel
TIMES = 4  # exposure instants when the scene moves; each takes a Latin-square quarter of the samples
# sample (i, j)'s instant: every row and every column of the 4x4 pattern sees all four instants
_INSTANT = np.array([[(i + 2 * j + j // 2) % TIMES for i in range(SUB)] for j in range(SUB)])


@dataclass
class SoftRender:
    rgb: F32  # H x W x 3, the pixel's mean colour (what the sensor sees)
    alpha: F32  # H x W, the share of the pixel the subject covers
    foreground: F32  # H x W x 3, the subject's colour unmixed (0 where alpha is 0)


def edge_band(scene: Scene, cam: RayCamera, centre: RenderResult) -> NDArray[np.bool_]:
    """The pixels to supersample: near a change of visible primitive, and every thin primitive's box."""
    ids = centre.ids
    change = np.zeros(ids.shape, bool)
    change[:, 1:] |= ids[:, 1:] != ids[:, :-1]
    change[:, :-1] |= ids[:, 1:] != ids[:, :-1]
    change[1:] |= ids[1:] != ids[:-1]
    change[:-1] |= ids[1:] != ids[:-1]
    band = cv2.dilate(change.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    for prim in scene.primitives:
        if prim.thin and (box := cam.project_box(prim.hull())) is not None:
            x0, y0, x1, y1 = box
            band[y0:y1, x0:x1] = True
    return np.asarray(band)


def supersample(
    scene_at: Callable[[float], Scene], cam: RayCamera, centre: RenderResult, moving: bool, exposure_s: float
) -> SoftRender:
    """``centre`` (the one-ray render of ``scene_at(0)``) with its edge band supersampled. ``scene_at(dt)`` is
    the scene ``dt`` seconds from the frame's instant, sampled over the exposure when ``moving``."""
    scene = scene_at(0.0)
    band = edge_band(scene, cam, centre)
    ys, xs = np.nonzero(band)
    order = np.lexsort((ys, xs))  # by column: a primitive's box is then one run of samples
    ys, xs = ys[order], xs[order]
    steps = (np.arange(SUB, dtype=np.float32) + 0.5) / SUB - 0.5
    instants = range(TIMES) if moving else [0]
    rgb_sum = np.zeros((len(xs), 3), np.float64)
    fg_sum = np.zeros((len(xs), 3), np.float64)
    hits = np.zeros(len(xs), np.float64)
    for k in instants:
        cells = np.argwhere(np.equal(_INSTANT, k) | (not moving))
        mx = (xs[None, :] + steps[cells[:, 1]][:, None]).astype(np.float32)
        my = (ys[None, :] + steps[cells[:, 0]][:, None]).astype(np.float32)
        # rays between pixel centres: the lens model is smooth, so bilinear between neighbours is exact to
        # far below a thousandth of a pixel
        dirs = _bilinear(cam.dirs, mx, my)
        sample_cam = RayCamera(cam.origin, np.ascontiguousarray(dirs, np.float32), cam.focal_px, _by_column(cam, xs))
        dt = ((k + 0.5) / TIMES - 0.5) * exposure_s if moving else 0.0
        res = render(scene_at(dt) if moving else scene, sample_cam)
        light = bt709_to_linear(res.rgb)  # a sensor adds light: the mix is linear, the picture's code values not
        rgb_sum += light.sum(axis=0)
        fg_sum += (light * res.subject[..., None]).sum(axis=0)
        hits += res.subject.sum(axis=0)
    n = float(SUB * SUB)
    rgb = centre.rgb.copy()
    rgb[ys, xs] = linear_to_bt709(rgb_sum / n)
    alpha = centre.subject.astype(np.float32)
    alpha[ys, xs] = (hits / n).astype(np.float32)
    foreground = np.where(centre.subject[..., None], centre.rgb, np.float32(0.0)).astype(np.float32)
    foreground[ys, xs] = np.where(hits[:, None] > 0, linear_to_bt709(fg_sum / np.maximum(hits, 1.0)[:, None]), 0.0)
    return SoftRender(rgb, alpha, foreground)


def _bilinear(img: F32, mx: F32, my: F32) -> F32:
    """``img`` (H x W x C) at fractional (mx, my), edge pixels extended (remap's maps stop at 32767 columns)."""
    h, w = img.shape[:2]
    x0 = np.clip(np.floor(mx).astype(np.intp), 0, w - 2)
    y0 = np.clip(np.floor(my).astype(np.intp), 0, h - 2)
    fx = np.clip(mx - x0, 0, 1)[..., None]
    fy = np.clip(my - y0, 0, 1)[..., None]
    top = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    bottom = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    return np.asarray(top * (1 - fy) + bottom * fy, np.float32)


Box = tuple[int, int, int, int]


def _by_column(cam: RayCamera, xs: NDArray[np.intp]) -> Callable[[NDArray[np.float64]], Box | None]:
    """Culling for samples laid out one column per band pixel, sorted by image column: the run of columns
    inside the primitive's box in the image (every row of samples)."""

    def project_box(corners: NDArray[np.float64]) -> Box | None:
        box = cam.project_box(corners)
        if box is None:
            return None
        j0, j1 = int(np.searchsorted(xs, box[0])), int(np.searchsorted(xs, box[2]))
        return None if j0 >= j1 else (j0, 0, j1, SUB * SUB)

    return project_box


def render_soft(array: SimArray, state: int, name: str, centre: RenderResult, rectified: bool) -> SoftRender:
    """One camera's soft render of ``state`` (``centre`` its one-ray render), through its captured rays or
    the rectified geometry's (where the truth lives)."""
    s = array.settings
    moving = s.scene == "presenter" and s.motion
    cam = array.rays(name, rectified)
    return supersample(lambda dt: array.scene(state, dt), cam, centre, moving, s.exposure_us * 1e-6)


def soft_truth(array: SimArray, state: int) -> tuple[list[F32], list[F32]]:
    """Per camera, in the rectified geometry of the true calibration: alpha and the unmixed foreground."""
    scene = array.scene(state)
    alphas, colours = [], []
    for n in array.names:
        centre = render(scene, array.rays(n, rectified=True))
        soft = render_soft(array, state, n, centre, rectified=True)
        alphas.append(soft.alpha)
        colours.append(soft.foreground)
    return alphas, colours
