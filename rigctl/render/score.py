"""Image quality of a rendered view against a reference image: PSNR, SSIM and IV-PSNR (MPEG's metric for
immersive video, ``rigctl.interop.ivpsnr``) on the reference's keyed subject (the whole image when it shows
no screen)."""

from __future__ import annotations

import logging
import math
from typing import TypedDict

import numpy as np
from numpy.typing import NDArray

log = logging.getLogger(__name__)

F32 = NDArray[np.float32]
PSNR_CAP_DB = 99.0  # identical images: a finite figure, never infinity


class Score(TypedDict):
    psnr_db: float
    ssim: float
    ivpsnr_db: float  # tolerates a shift of up to 2 px and a colour offset a viewer does not notice
    pixels: int  # the subject's pixels scored


def psnr_db(rendered: F32, reference: F32, mask: NDArray[np.bool_]) -> float:
    """PSNR over the masked pixels (all three channels), peak 1.0, capped at ``PSNR_CAP_DB``."""
    if not mask.any():
        raise ValueError("no pixels to score")
    diff = rendered[mask] - reference[mask]
    mse = float(np.mean(diff.astype(np.float64) ** 2))
    return PSNR_CAP_DB if mse <= 10 ** (-PSNR_CAP_DB / 10) else -10.0 * math.log10(mse)


def ssim(rendered: F32, reference: F32, mask: NDArray[np.bool_]) -> float:
    """Mean of the SSIM map (Gaussian window, sigma 1.5, as Wang et al. 2004) over the masked pixels,
    computed on the mask's bounding box widened by the window."""
    from skimage.metrics import structural_similarity

    ys, xs = np.nonzero(mask)
    if not ys.size:
        raise ValueError("no pixels to score")
    h, w = mask.shape
    y0, y1 = max(0, ys.min() - 8), min(h, ys.max() + 9)
    x0, x1 = max(0, xs.min() - 8), min(w, xs.max() + 9)
    _, smap = structural_similarity(
        reference[y0:y1, x0:x1],
        rendered[y0:y1, x0:x1],
        channel_axis=2,
        data_range=1.0,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        full=True,
    )
    return float(np.mean(smap.mean(axis=2)[mask[y0:y1, x0:x1]]))


def score(
    rendered: F32, reference: F32, reference_alpha: F32, ignore: tuple[int, int, int, int] | None = None
) -> Score:
    """PSNR (dB), SSIM and the pixel count on the reference's subject (alpha > 0.5). ``ignore`` =
    (y0, y1, x0, x1) leaves out a window that differs between cameras by design (a simulated take's burnt-in
    frame id, which no view of the scene can reproduce)."""
    mask = reference_alpha > 0.5
    if not mask.any():
        mask = np.ones(mask.shape, bool)
    if ignore is not None:
        y0, y1, x0, x1 = ignore
        mask[y0:y1, x0:x1] = False
    from rigctl.interop.ivpsnr import ivpsnr_rgb

    return {
        "psnr_db": round(psnr_db(rendered, reference, mask), 3),
        "ssim": round(ssim(rendered, reference, mask), 4),
        "ivpsnr_db": round(ivpsnr_rgb(rendered, reference, mask), 3),
        "pixels": int(mask.sum()),
    }


def full_frame_psnr_db(
    rendered_rgba: F32, reference: F32, reference_alpha: F32, ignore: tuple[int, int, int, int] | None = None
) -> float:
    """PSNR (dB) over the whole frame of the rendered subject against the reference's keyed subject, both
    premultiplied by their alpha (straight RGBA in, as a renderer writes it): where the reference shows
    screen, anything the render puts there (a fringe of depth painted beside the silhouette) costs as much
    as an error on the subject, and so does a part of the subject the render leaves out. ``ignore`` as in
    :func:`score`."""
    mask = np.ones(reference_alpha.shape, bool)
    if ignore is not None:
        y0, y1, x0, x1 = ignore
        mask[y0:y1, x0:x1] = False
    ours = rendered_rgba[..., :3] * rendered_rgba[..., 3:4]
    theirs = reference * reference_alpha[..., None]
    return round(psnr_db(ours.astype(np.float32), theirs.astype(np.float32), mask), 3)
