"""What a calibration is judged by: the rig frame it is written in, coverage and conditioning checks that name
the camera and what to shoot, cross-validation, rectification residuals on held-out corners, and (for
simulated takes) the error against the truth."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.calib.detect import Observations
from rigctl.calib.report_model import DisparityRatio, ErrorStats, PairResidual, RawNet, RectificationResiduals
from rigctl.calib.solution import F64, Solution, chordal_mean
from rigctl.calibration_model import ArrayCalibration, CameraModel, rotation_angle_deg
from rigctl.rectification.geometry import common_plane

MIN_POSES = 4
MIN_VIEWS_CAMERA = 3
MIN_TILT_DEG = 10.0
MIN_COVERAGE = 0.5  # of a 6 x 4 grid of image cells
MIN_CORNER_CELLS = 1  # of the 4 image corner cells
MAX_REL_FOCAL_SIGMA = 1e-3


def to_rig(
    sol: Solution,
    names: list[str],
    sizes: list[tuple[int, int]],
    rig: str,
    nominal: dict[str, F64] | None = None,
    meta: dict[str, object] | None = None,
) -> ArrayCalibration:
    """The solution in a rig frame: axes = the cameras' mean orientation (chordal mean); origin such that the
    centres fit the nominal lattice best (translation only), or their centroid without a nominal lattice."""
    Rs = [sol.R(c) for c in range(len(names))]
    Cs = np.stack([-Rs[c].T @ sol.tvec[c] for c in range(len(names))])
    Rm = chordal_mean(Rs)  # camera-0 frame -> mean camera frame
    if nominal is not None:
        nom = np.stack([nominal[n] for n in names])
        origin = Cs.mean(0) - Rm.T @ nom.mean(0)
    else:
        origin = Cs.mean(0)
    cams = {}
    for c, n in enumerate(names):
        R = Rs[c] @ Rm.T
        C = Rm @ (Cs[c] - origin)
        cams[n] = CameraModel(n, sol.K[c].copy(), np.asarray(sol.dist[c], float).copy(), R, -R @ C, sizes[c])
    ref = "r1c1" if "r1c1" in cams else names[0]
    return ArrayCalibration(rig=rig, cameras=cams, reference=ref, meta=meta or {})


# ---- checks ------------------------------------------------------------------------------------------------
def coverage(obs: Observations, c: int, size: tuple[int, int], active: NDArray[np.bool_]) -> tuple[float, int]:
    """Share of a 6 x 4 grid of image cells holding corners, and how many of the 4 corner cells do."""
    m = (obs.cam == c) & active[obs.cam, obs.frame]
    w, h = size
    ix = np.clip((obs.uv[m, 0] / w * 6).astype(int), 0, 5)
    iy = np.clip((obs.uv[m, 1] / h * 4).astype(int), 0, 3)
    cells = np.zeros((4, 6), bool)
    cells[iy, ix] = True
    return float(cells.mean()), int(cells[0, 0]) + int(cells[0, -1]) + int(cells[-1, 0]) + int(cells[-1, -1])


def coverage_map(obs: Observations, c: int, size: tuple[int, int], active: NDArray[np.bool_]) -> F64:
    m = (obs.cam == c) & active[obs.cam, obs.frame]
    return np.asarray(obs.uv[m], dtype=np.float64)


def max_tilt_deg(sol: Solution, c: int, frames: NDArray[np.int64]) -> float:
    """Largest angle between the board's normal and camera c's axis over ``frames``."""
    Rc = sol.R(c)
    best = 0.0
    for f in frames:
        if np.all(np.isfinite(sol.frame_rvec[f])):
            n = Rc @ cv2.Rodrigues(sol.frame_rvec[f])[0][:, 2]
            best = max(best, float(np.degrees(np.arccos(min(1.0, abs(float(n[2])))))))
    return best


def distortion_monotonic(K: F64, dist: F64, size: tuple[int, int]) -> bool:
    """Does the radial model r_d = r (1 + k1 r^2 + k2 r^4 + k3 r^6) keep rising out to the farthest image
    corner? (Where it folds over, undistortion is ambiguous and the fit extrapolates.)"""
    k1, k2, _, _, k3 = np.ravel(dist)[:5]
    w, h = size
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], float)
    rd_max = float(np.max(np.hypot((corners[:, 0] - K[0, 2]) / K[0, 0], (corners[:, 1] - K[1, 2]) / K[1, 1])))
    r = np.linspace(0, 3 * rd_max + 1e-9, 20000)
    rd = r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)
    reach = np.flatnonzero(rd >= rd_max)
    return bool(len(reach) and np.all(np.diff(rd)[: reach[0]] > 0))


def diagnose(
    names: list[str],
    obs: Observations,
    sizes: list[tuple[int, int]],
    sol: Solution | None,
    active: NDArray[np.bool_],
    length_unit_m: float | None = 1.0,
) -> list[str]:
    """Problems that make a calibration untrustworthy, each naming the camera and what to shoot."""
    out = []
    poses = int(active.any(0).sum())
    if poses < MIN_POSES:
        out.append(
            f"only {poses} usable board views in the whole take (need {MIN_POSES} or more): record more board "
            "poses, tilted 20-40 degrees in different directions"
        )
    for c, n in enumerate(names):
        k = int(active[c].sum())
        if k < MIN_VIEWS_CAMERA:
            out.append(
                f"camera {n} sees the board in {k} views (need {MIN_VIEWS_CAMERA} or more): hold the board in its view"
            )
        cov, cc = coverage(obs, c, sizes[c], active)
        if cov < MIN_COVERAGE or cc < MIN_CORNER_CELLS:
            out.append(
                f"camera {n}: corners cover {cov:.0%} of the image and {cc} of its 4 corners: "
                f"move the board towards the edges and corners of {n}'s view"
            )
        if sol is None:
            continue
        tilt = max_tilt_deg(sol, c, np.flatnonzero(active[c]))
        if tilt < MIN_TILT_DEG:
            out.append(
                f"camera {n}: every board is nearly fronto-parallel (largest tilt {tilt:.1f} degrees): "
                "tilt the board 20-40 degrees about both axes"
            )
        if not distortion_monotonic(sol.K[c], sol.dist[c], sizes[c]):
            out.append(
                f"camera {n}: the fitted distortion folds over before the image corners: show the board in "
                f"{n}'s corners (or fit fewer coefficients)"
            )
        unc = [u.as_dict() for u in sol.info.uncertainty]
        if unc:
            f = float(sol.K[c][0, 0])
            if unc[c]["fx"] / f > MAX_REL_FOCAL_SIGMA:
                out.append(
                    f"camera {n}: focal length uncertain (+-{unc[c]['fx']:.1f} px): tilt the board more and vary "
                    "its distance"
                )
            if length_unit_m and c > 0 and unc[c].get("centre", 0.0) * length_unit_m > 0.5e-3:
                out.append(
                    f"camera {n}: position uncertain (+-{unc[c]['centre'] * length_unit_m * 1e3:.2f} mm): show the "
                    "board to it together with its neighbours more often"
                )
    return out


# ---- comparisons -----------------------------------------------------------------------------------------------
def _pixel_grid(size: tuple[int, int], nx: int = 9, ny: int = 6) -> F64:
    w, h = size
    g = np.stack(np.meshgrid(np.linspace(0, w - 1, nx), np.linspace(0, h - 1, ny)), -1)
    return np.asarray(g.reshape(-1, 1, 2), dtype=np.float64)


def _rays(cam: CameraModel, uv: F64) -> F64:
    n = cv2.undistortPoints(uv, cam.K, cam.dist, criteria=(3, 50, 1e-12)).reshape(-1, 2)
    r = np.column_stack([n, np.ones(len(n))]) @ cam.R
    return np.asarray(r / np.linalg.norm(r, axis=1, keepdims=True), dtype=np.float64)


def align_rays(a: ArrayCalibration, b: ArrayCalibration) -> tuple[F64, F64]:
    """(A, t) taking a's rig frame to b's: A aligns the rays of every camera's pixel grid (Kabsch on unit
    vectors), t the centres. Aligning on R alone inherits its trade-off with the principal point."""
    H = np.zeros((3, 3))
    for n in a.names:
        g = _pixel_grid(a[n].image_size)
        H += _rays(a[n], g).T @ _rays(b[n], g)
    U, _, Vt = np.linalg.svd(H)
    A = Vt.T @ np.diag([1, 1, np.linalg.det(Vt.T @ U.T)]) @ U.T
    t = np.mean([b[n].centre - A @ a[n].centre for n in a.names], axis=0)
    return np.asarray(A, dtype=np.float64), np.asarray(t, dtype=np.float64)


def compare_to_truth(est: ArrayCalibration, truth: ArrayCalibration) -> dict[str, dict[str, float]]:
    """Per camera after aligning the rig frames (rotation from the orientations, translation from the
    centres): centre error (mm), rotation error (degrees), worst ray direction error over the image
    (degrees, frames aligned on the rays), focal length error (px)."""
    A = chordal_mean([truth[n].R.T @ est[n].R for n in est.names])
    b = np.mean([truth[n].centre - A @ est[n].centre for n in est.names], axis=0)
    Ar, _ = align_rays(est, truth)
    out = {}
    for n in est.names:
        e, t = est[n], truth[n]
        g = _pixel_grid(t.image_size)
        ray = np.degrees(np.arccos(np.clip(np.sum((_rays(e, g) @ Ar.T) * _rays(t, g), 1), -1, 1)))
        out[n] = {
            "centre_mm": float(np.linalg.norm(A @ e.centre + b - t.centre) * 1e3),
            "rotation_deg": rotation_angle_deg(e.R @ A.T @ t.R.T),
            "ray_deg": float(ray.max()),
            "focal_px": float(e.K[0, 0] - t.K[0, 0]),
        }
    return out


def cross_validate(a: ArrayCalibration, b: ArrayCalibration, depth: tuple[float, float]) -> dict[str, float]:
    """How far two calibrations disagree, in pixels of reprojection: points over each camera's view at
    ``depth`` (the board distances), projected by both after aligning a's rig frame onto b's (on the rays)."""
    A, tt = align_rays(a, b)
    out = {}
    for n in a.names:
        ca, cb = a[n], b[n]
        w, h = ca.image_size
        uv = np.stack(np.meshgrid(np.linspace(0, w - 1, 12), np.linspace(0, h - 1, 7)), -1).reshape(-1, 1, 2)
        ray = cv2.undistortPoints(uv.astype(np.float64), ca.K, ca.dist).reshape(-1, 2)
        diffs = []
        for z in np.linspace(depth[0], depth[1], 4):
            Xc = np.column_stack([ray * z, np.full(len(ray), z)])
            Xr = (Xc - ca.t) @ ca.R
            diffs.append(cb.project(Xr @ A.T + tt) - ca.project(Xr))
        d = np.concatenate(diffs)
        out[n] = float(np.sqrt(np.mean((d**2).sum(1))))
    return out


def _stats(d: F64) -> ErrorStats:
    if not len(d):
        return ErrorStats(float("nan"), float("nan"), float("nan"), 0)
    a = np.abs(d)
    return ErrorStats(float(np.sqrt(np.mean(d**2))), float(np.percentile(a, 95)), float(a.max()), len(d))


def rectification_residuals(
    calib: ArrayCalibration, obs: Observations, names: list[str], frames: list[int]
) -> RectificationResiduals:
    """On the corners of ``frames`` (held out of the fit): after common-plane rectification, the vertical
    disparity between horizontal neighbours and the horizontal disparity between vertical neighbours, per
    pair and overall, and the ratio of horizontal to vertical disparity against dx / dy.

    ``raw`` is what matching sees. ``net`` subtracts the parallax that the cameras' fitted positions off the
    lattice predict for each corner (the baseline's small cross component times the corner's own disparity
    along the baseline): what is left is the rectification's own error. No rotation and shared matrix can
    remove that parallax; it scales with 1/Z and the depth stage has to live with it."""
    grid = common_plane(calib)
    idx = {n: i for i, n in enumerate(names)}
    pos = {n: calib[n].grid_position for n in names}
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    rect: dict[tuple[str, int], dict[int, F64]] = {}
    for n in names:
        cam = calib[n]
        for f in frames:
            m = (obs.cam == idx[n]) & (obs.frame == f)
            if m.any():
                p = cv2.undistortPoints(
                    obs.uv[m].reshape(-1, 1, 2),
                    cam.K,
                    cam.dist,
                    R=grid.rectifying_rotation(cam),
                    P=grid.K,
                    criteria=crit,
                ).reshape(-1, 2)
                rect[n, f] = dict(zip(obs.pt[m].tolist(), p, strict=True))
    pairs: dict[str, PairResidual] = {}
    pooled: dict[str, list[F64]] = {"h_raw": [], "h_net": [], "v_raw": [], "v_net": []}
    for a in names:
        for b in names:
            (ra, ca), (rb, cb) = pos[a], pos[b]
            horizontal = ra == rb and cb == ca + 1
            vertical = ca == cb and rb == ra + 1
            if not (horizontal or vertical):
                continue
            base = grid.position_m(b) - grid.position_m(a)
            raw, net = [], []
            for f in frames:
                if (a, f) not in rect or (b, f) not in rect:
                    continue
                common = sorted(set(rect[a, f]) & set(rect[b, f]))
                if not common:
                    continue
                d = np.stack([rect[a, f][k] - rect[b, f][k] for k in common])  # disparity vector a -> b
                if horizontal:
                    main, cross, ratio = d[:, 0], d[:, 1], base[1] / base[0]
                else:
                    main, cross, ratio = d[:, 1], d[:, 0], base[0] / base[1]
                raw.append(cross)
                net.append(cross - main * ratio)
            if not raw:
                continue
            r, nt = np.concatenate(raw), np.concatenate(net)
            key = "h" if horizontal else "v"
            pooled[f"{key}_raw"].append(r)
            pooled[f"{key}_net"].append(nt)
            pairs[f"{a}-{b}"] = PairResidual("horizontal" if horizontal else "vertical", _stats(r), _stats(nt))

    def pooled_stats(key: str) -> RawNet:
        raw, net = pooled[f"{key}_raw"], pooled[f"{key}_net"]
        return RawNet(
            _stats(np.concatenate(raw) if raw else np.zeros(0)), _stats(np.concatenate(net) if net else np.zeros(0))
        )

    return RectificationResiduals(
        len(frames), pooled_stats("h"), pooled_stats("v"), pairs, _disparity_ratio(rect, names, pos, frames, grid)
    )


def _disparity_ratio(
    rect: dict[tuple[str, int], dict[int, F64]],
    names: list[str],
    pos: dict[str, tuple[int, int]],
    frames: list[int],
    grid: Any,
) -> DisparityRatio | None:
    """Horizontal disparity to the right neighbour over vertical disparity to the neighbour below, for the
    same corner, against dx / dy of the fitted grid (1.0 = the grid's geometry holds)."""
    ratios = []
    for a in names:
        r, c = pos[a]
        right = next((n for n in names if pos[n] == (r, c + 1)), None)
        below = next((n for n in names if pos[n] == (r + 1, c)), None)
        if right is None or below is None:
            continue
        for f in frames:
            if (a, f) not in rect or (right, f) not in rect or (below, f) not in rect:
                continue
            for k in set(rect[a, f]) & set(rect[right, f]) & set(rect[below, f]):
                dx = rect[a, f][k][0] - rect[right, f][k][0]
                dy = rect[a, f][k][1] - rect[below, f][k][1]
                if abs(dy) > 1.0:
                    ratios.append(dx / dy)
    if not ratios:
        return None
    expected = grid.spacing_x_m / grid.spacing_y_m
    return DisparityRatio(float(np.median(ratios)), expected, float(np.median(ratios) / expected))
