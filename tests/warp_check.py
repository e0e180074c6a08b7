"""Checking images against true disparity: warp a neighbour by the disparity and compare with the reference
camera (shared by the simulator's truth tests and the rectification tests)."""

from __future__ import annotations

import cv2
import numpy as np

STEP = {"r1c2": (1, 0), "r1c0": (-1, 0), "r2c1": (0, 1), "r0c1": (0, -1)}  # (columns, rows) from r1c1


def warp_into(img: np.ndarray, disp: np.ndarray, bx: float, by: float) -> np.ndarray:
    """Sample ``img`` (a neighbour) where each reference pixel's point appears: x - d * bx, y - d * by, with
    the neighbour's offset (bx, by) in units of the horizontal spacing. On a perfect lattice this is the
    contract's rule (bx = k - j, by = dy/dx * (m - i))."""
    h, w = disp.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    d = np.where(np.isfinite(disp), disp, 0).astype(np.float32)
    mx, my = (xs - d * np.float32(bx)).astype(np.float32), (ys - d * np.float32(by)).astype(np.float32)
    return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1)


def consistent(disp_ref: np.ndarray, disp_nb: np.ndarray, bx: float, by: float) -> np.ndarray:
    """Reference pixels whose point is also visible in the neighbour (its truth agrees), away from edges."""
    seen = warp_into(np.where(np.isfinite(disp_nb), disp_nb, -100).astype(np.float32), disp_ref, bx, by)
    ok = np.isfinite(disp_ref) & (np.abs(seen - disp_ref) < 0.3)
    ok = cv2.erode(ok.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    ok[:12, :120] = False  # the burnt-in id
    return ok


def mae_against_neighbours(
    images: dict[str, np.ndarray], disps: dict[str, np.ndarray], offsets: dict[str, tuple[float, float]]
) -> dict[str, tuple[float, int]]:
    out = {}
    for name in STEP:
        bx, by = offsets[name]
        ok = consistent(disps["r1c1"], disps[name], bx, by)
        warped = warp_into(images[name], disps["r1c1"], bx, by)
        out[name] = (float(np.mean(np.abs(warped[ok] - images["r1c1"][ok]))), int(ok.sum()))
    return out


def lattice_offsets(ratio: float) -> dict[str, tuple[float, float]]:
    return {n: (dc, dr * ratio) for n, (dc, dr) in STEP.items()}
