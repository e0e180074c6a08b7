"""A joint calibration's unknowns and how they project: every camera's intrinsics and pose, every board pose,
with the fit's figures (typed), the projection with OpenCV's 5-term distortion model, and residuals per view.
Conventions: camera c maps camera-0 coordinates to its own, X_c = R_c X_0 + t_c; frame f's board pose maps
board to camera 0, X_0 = R_f X_b + t_f."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.calib.detect import Observations

F64 = NDArray[np.float64]
DIST_NAMES = ("k1", "k2", "p1", "p2", "k3")


@dataclass
class CameraUncertainty:
    """1-sigma uncertainties of one camera after the bundle adjustment: the intrinsics (fx fy cx cy and the
    free distortion terms, by name), the rotation (degrees) and the centre (board units) of cameras past
    the first."""

    intrinsics: dict[str, float]
    rotation_deg: float | None = None
    centre: float | None = None

    def as_dict(self) -> dict[str, float]:
        out = dict(self.intrinsics)
        if self.rotation_deg is not None:
            out["rotation_deg"] = self.rotation_deg
        if self.centre is not None:
            out["centre"] = self.centre
        return out


@dataclass
class FitInfo:
    """How a solution was reached: its run time, where it came from, and the bundle adjustment's figures."""

    seconds: float = 0.0
    init: str = ""  # the initial solution's source ("" for a bundle adjustment)
    iterations: int = 0
    status: str = ""
    sigma_px: float = math.nan
    uncertainty: list[CameraUncertainty] = field(default_factory=list)


@dataclass
class Solution:
    K: list[F64]
    dist: list[F64]  # (5,) each: k1 k2 p1 p2 k3
    rvec: F64  # (C, 3) camera 0 -> camera c
    tvec: F64  # (C, 3)
    frame_rvec: F64  # (F, 3) board -> camera 0, NaN where unknown
    frame_tvec: F64
    rms: float = float("nan")
    info: FitInfo = field(default_factory=FitInfo)

    def R(self, c: int) -> F64:
        return np.asarray(cv2.Rodrigues(self.rvec[c])[0], dtype=np.float64)


def rodrigues_many(r: F64) -> F64:
    th = np.linalg.norm(r, axis=1)
    small = th < 1e-12
    k = r / np.where(small, 1.0, th)[:, None]
    S = np.zeros((len(r), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(th)[:, None, None], np.cos(th)[:, None, None]
    R = np.eye(3)[None] + s * S + (1 - c) * (S @ S)
    R[small] = np.eye(3)
    return np.asarray(R, dtype=np.float64)


def project(P: F64, K: F64, D: F64) -> F64:
    """Camera-frame points (M,3) to pixels with OpenCV's 5-term model; per-point K (M,3,3) and D (M,5)."""
    x, y = P[:, 0] / P[:, 2], P[:, 1] / P[:, 2]
    r2 = x * x + y * y
    k1, k2, p1, p2, k3 = D.T
    rad = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([K[:, 0, 0] * xd + K[:, 0, 2], K[:, 1, 1] * yd + K[:, 1, 2]], axis=1)


def reprojection(sol: Solution, points: F64, obs: Observations) -> F64:
    """Residuals (M, 2): projected minus observed."""
    Rf = rodrigues_many(sol.frame_rvec[obs.frame])
    X0 = np.einsum("mij,mj->mi", Rf, points[obs.pt]) + sol.frame_tvec[obs.frame]
    Rc = rodrigues_many(sol.rvec)
    Xc = np.einsum("mij,mj->mi", Rc[obs.cam], X0) + sol.tvec[obs.cam]
    K = np.stack(sol.K)[obs.cam]
    D = np.stack([np.ravel(d)[:5] for d in sol.dist])[obs.cam]
    return project(Xc, K, D) - obs.uv


def view_rms(res: F64, obs: Observations) -> F64:
    """(cameras, frames): RMS of the 2-D error per view, NaN where there are no corners."""
    s = np.zeros((obs.n_cams, obs.n_frames))
    n = np.zeros((obs.n_cams, obs.n_frames))
    np.add.at(s, (obs.cam, obs.frame), (res**2).sum(1))
    np.add.at(n, (obs.cam, obs.frame), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(np.sqrt(s / n), dtype=np.float64)


def view_rms_masked(res: F64, obs: Observations, keep: NDArray[np.bool_]) -> F64:
    """view_rms over the kept corners only."""
    return view_rms(res[keep], obs.subset(keep))


def rms(res: F64) -> float:
    return float(np.sqrt((res**2).sum(1).mean())) if len(res) else float("nan")


def chordal_mean(Rs: list[F64]) -> F64:
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    return np.asarray(U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt, dtype=np.float64)
