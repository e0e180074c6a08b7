"""Joint calibration of all cameras from planar-target corners: an initial solution from OpenCV 5's
``calibrateMultiviewExtended`` (or, when that cannot run, per-camera ``calibrateCamera`` chained over a
spanning tree), refined by a bundle adjustment over every intrinsic, camera pose and board pose, with
gradual rejection of views far above the median error and re-admission of those that fit the final result.

Why a bundle adjustment: OpenCV 5.0's multiview calibration refines extrinsics only; each camera keeps the
intrinsics of its own ``calibrateCamera``, which leaves camera centres 1-2 mm and rotations 0.04 degrees
off on the simulated rig. Conventions: camera c maps camera-0 coordinates to its own, X_c = R_c X_0 + t_c;
frame f's board pose maps board to camera 0, X_0 = R_f X_b + t_f.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve
from scipy.sparse import csr_matrix

from rigctl.calib.detect import Observations
from rigctl.errors import CalibrationError

F64 = NDArray[np.float64]
DIST_NAMES = ("k1", "k2", "p1", "p2", "k3")
MODELS = {
    "k1k2": ((True, True, False, False, False), cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST),
    "k1k2k3": ((True, True, False, False, True), cv2.CALIB_ZERO_TANGENT_DIST),
    "full": ((True, True, True, True, True), 0),
}


@dataclass
class Solution:
    K: list[F64]
    dist: list[F64]  # (5,) each: k1 k2 p1 p2 k3
    rvec: F64  # (C, 3) camera 0 -> camera c
    tvec: F64  # (C, 3)
    frame_rvec: F64  # (F, 3) board -> camera 0, NaN where unknown
    frame_tvec: F64
    rms: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)

    def R(self, c: int) -> F64:
        return np.asarray(cv2.Rodrigues(self.rvec[c])[0], dtype=np.float64)


def _rodrigues_many(r: F64) -> F64:
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


def _project(P: F64, K: F64, D: F64) -> F64:
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
    Rf = _rodrigues_many(sol.frame_rvec[obs.frame])
    X0 = np.einsum("mij,mj->mi", Rf, points[obs.pt]) + sol.frame_tvec[obs.frame]
    Rc = _rodrigues_many(sol.rvec)
    Xc = np.einsum("mij,mj->mi", Rc[obs.cam], X0) + sol.tvec[obs.cam]
    K = np.stack(sol.K)[obs.cam]
    D = np.stack([np.ravel(d)[:5] for d in sol.dist])[obs.cam]
    return _project(Xc, K, D) - obs.uv


def view_rms(res: F64, obs: Observations) -> F64:
    """(cameras, frames): RMS of the 2-D error per view, NaN where there are no corners."""
    s = np.zeros((obs.n_cams, obs.n_frames))
    n = np.zeros((obs.n_cams, obs.n_frames))
    np.add.at(s, (obs.cam, obs.frame), (res**2).sum(1))
    np.add.at(n, (obs.cam, obs.frame), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(np.sqrt(s / n), dtype=np.float64)


def _view_rms_masked(res: F64, obs: Observations, keep: NDArray[np.bool_]) -> F64:
    """view_rms over the kept corners only."""
    return view_rms(res[keep], obs.subset(keep))


CORNER_FACTOR = 5.0  # a single corner this many times the median corner error ...
CORNER_MIN_PX = 0.5  # ... and above this is a mis-detection, not noise


def rms(res: F64) -> float:
    return float(np.sqrt((res**2).sum(1).mean())) if len(res) else float("nan")


def object_scale(points: F64) -> float:
    """A factor taking the board to diameter 1: OpenCV 5.0 divides object points by the squared diameter and
    then calls any board wider than about 20 units "collinear" (millimetres and centimetres fail)."""
    d = float(np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2).max())
    if not d > 0:
        raise CalibrationError("the calibration target's points are all at one place")
    return 1.0 / d


def opencv_init(points: F64, obs: Observations, sizes: list[tuple[int, int]], flags: int) -> Solution:
    """cv2.calibrateMultiviewExtended on the views that show the whole board (the 5.0 wheel mishandles the
    (-1, -1) placeholders of partly seen boards: its per-camera calibrateCamera diverges)."""
    C, F, N = obs.n_cams, obs.n_frames, len(points)
    s = object_scale(points)
    objp = [(points * s).astype(np.float32)] * F
    imgp = np.full((C, F, N, 2), -1.0, np.float32)
    imgp[obs.cam, obs.frame, obs.pt] = obs.uv
    mask = (obs.views() >= N).astype(np.uint8)
    models = np.full(C, cv2.CALIB_MODEL_PINHOLE, np.uint8)
    per_cam = np.full(C, flags, np.int32)
    t0 = time.perf_counter()
    out = cv2.calibrateMultiviewExtended(  # type: ignore[call-overload]  # the stubs want Ks etc. given
        objp,
        [[imgp[c, f] for f in range(F)] for c in range(C)],
        list(sizes),
        mask,
        models,
        None,
        None,
        None,
        None,
        flagsForIntrinsics=per_cam,
    )
    err, Ks, ds, Rs, Ts, pairs, rv0, tv0, _ = out
    frame_r = np.full((F, 3), np.nan)
    frame_t = np.full((F, 3), np.nan)
    for f in range(F):
        if rv0[f] is not None and np.size(rv0[f]) == 3:
            frame_r[f] = np.ravel(rv0[f])
            frame_t[f] = np.ravel(tv0[f]) / s
    dist = []
    for d in ds:
        d5 = np.zeros(5)
        d5[: min(5, np.size(d))] = np.ravel(d)[:5]
        dist.append(d5)
    return Solution(
        [np.asarray(k, np.float64) for k in Ks],
        dist,
        np.stack([np.ravel(r) for r in Rs]).astype(np.float64),
        np.stack([np.ravel(t) for t in Ts]).astype(np.float64) / s,
        frame_r,
        frame_t,
        float(err),
        {
            "seconds": time.perf_counter() - t0,
            "init": "calibrateMultiviewExtended",
            "pairs": np.asarray(pairs).tolist(),
        },
    )


def _chordal_mean(Rs: list[F64]) -> F64:
    U, _, Vt = np.linalg.svd(np.sum(Rs, axis=0))
    return np.asarray(U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt, dtype=np.float64)


def own_init(
    points: F64, obs: Observations, sizes: list[tuple[int, int]], flags: int, names: list[str], min_corners: int = 6
) -> Solution:
    """Without calibrateMultiview (handles partly seen boards): calibrateCamera per camera, relative poses as
    the chordal mean over shared views, chained over a maximum spanning tree from camera 0."""
    C, F = obs.n_cams, obs.n_frames
    views = obs.views() >= min_corners
    Ks, ds, poses = [], [], {}
    for c in range(C):
        fr = np.flatnonzero(views[c])
        if len(fr) == 0:
            raise CalibrationError(f"camera {names[c]} sees the board in no view: hold the board in its view")
        objs, imgs = [], []
        for view in fr:
            m = (obs.cam == c) & (obs.frame == view)
            objs.append(points[obs.pt[m]].astype(np.float32))
            imgs.append(obs.uv[m].astype(np.float32))
        try:
            _, K, d, rv, tv = cv2.calibrateCamera(objs, imgs, tuple(sizes[c]), None, None, flags=flags)
        except cv2.error as exc:
            raise CalibrationError(f"camera {names[c]}: OpenCV could not calibrate it: {_cv_message(exc)}") from None
        Ks.append(np.asarray(K, np.float64))
        d5 = np.zeros(5)
        d5[: min(5, d.size)] = d.ravel()[:5]
        ds.append(d5)
        for view, r, t in zip(fr, rv, tv, strict=True):
            poses[c, int(view)] = (cv2.Rodrigues(r)[0], t.ravel())
    shared = views.astype(int) @ views.T.astype(int)
    Rw: dict[int, F64] = {0: np.eye(3)}
    tw: dict[int, F64] = {0: np.zeros(3)}
    while len(Rw) < C:
        n, a, b = max(((int(shared[a, b]), a, b) for a in Rw for b in range(C) if b not in Rw), default=(0, -1, -1))
        if n == 0:
            lone = [names[c] for c in range(C) if c not in Rw]
            raise CalibrationError(
                f"camera(s) {', '.join(lone)} never see the board together with {names[0]}'s group: "
                "hold the board where neighbouring cameras see it at the same time"
            )
        Rs, ts = [], []
        for shared_f in np.flatnonzero(views[a] & views[b]):
            Ra, ta = poses[a, int(shared_f)]
            Rb, tb = poses[b, int(shared_f)]
            Rab = Rb @ Ra.T
            Rs.append(Rab)
            ts.append(tb - Rab @ ta)
        Rab = _chordal_mean(Rs)
        tab = np.median(np.stack(ts), axis=0)
        Rw[b] = Rab @ Rw[a]
        tw[b] = Rab @ tw[a] + tab
    fr_r = np.full((F, 3), np.nan)
    fr_t = np.full((F, 3), np.nan)
    for f in range(F):
        cs = [c for c in range(C) if (c, f) in poses]
        if cs:
            c = cs[0]
            Rc, tc = poses[c, f]
            fr_r[f] = cv2.Rodrigues(Rw[c].T @ Rc)[0].ravel()
            fr_t[f] = Rw[c].T @ (tc - tw[c])
    return Solution(
        Ks,
        ds,
        np.stack([cv2.Rodrigues(Rw[c])[0].ravel() for c in range(C)]),
        np.stack([tw[c] for c in range(C)]),
        fr_r,
        fr_t,
        info={"seconds": 0.0, "init": "per-camera calibrateCamera + spanning tree"},
    )


def _fill_frame_poses(points: F64, obs: Observations, sol: Solution, active: NDArray[np.bool_]) -> None:
    """Board poses the initial solution left out: solvePnP in a camera that sees the board."""
    for f in range(obs.n_frames):
        if np.all(np.isfinite(sol.frame_rvec[f])) or not active[:, f].any():
            continue
        c = int(np.flatnonzero(active[:, f])[0])
        m = (obs.cam == c) & (obs.frame == f)
        ok, rv, tv = cv2.solvePnP(points[obs.pt[m]], obs.uv[m], sol.K[c], sol.dist[c])
        if not ok:
            continue
        Rc = sol.R(c)
        sol.frame_rvec[f] = cv2.Rodrigues(Rc.T @ cv2.Rodrigues(rv)[0])[0].ravel()
        sol.frame_tvec[f] = Rc.T @ (tv.ravel() - sol.tvec[c])


def _levenberg_marquardt(
    fun: Callable[[F64], F64], jac: Callable[[F64], Any], x: F64, max_iter: int = 100, tol: float = 1e-12
) -> tuple[F64, F64, int, str]:
    """Levenberg-Marquardt on the normal equations (sparse J, dense J^T J of a few hundred parameters;
    a full-Jacobian SVD as in scipy's trust-region solvers is 10-60x slower here)."""
    r = fun(x)
    cost = float(r @ r)
    lam = 1e-3
    status = "iteration limit"
    it = 0
    for it in range(1, max_iter + 1):
        J = jac(x)
        A = (J.T @ J).toarray()
        g = J.T @ r
        d = np.diag(A).copy()
        d[d <= 0] = 1.0
        while True:
            try:
                step = -cho_solve(cho_factor(A + lam * np.diag(d)), g)
            except np.linalg.LinAlgError:
                lam *= 10
                if lam > 1e12:
                    return x, r, it, "singular"
                continue
            x_new = x + step
            r_new = fun(x_new)
            c_new = float(r_new @ r_new) if np.all(np.isfinite(r_new)) else np.inf
            if c_new < cost:
                break
            lam *= 10
            if lam > 1e12:
                return x, r, it, "converged (no further decrease)"
        rel = (cost - c_new) / cost if cost > 0 else 0.0
        x, r, cost = x_new, r_new, c_new
        lam = max(lam / 10, 1e-12)
        if rel < tol or np.max(np.abs(step) / (np.abs(x) + 1e-8)) < tol:
            status = "converged"
            break
    return x, r, it, status


def bundle_adjust(
    points: F64, obs: Observations, sol: Solution, free_dist: tuple[bool, ...], max_iter: int = 100
) -> Solution:
    """Refine every intrinsic, camera pose (camera 0 fixed) and board pose; 1-sigma uncertainties in info."""
    C = obs.n_cams
    frames = np.unique(obs.frame)
    fidx = -np.ones(obs.n_frames, int)
    fidx[frames] = np.arange(len(frames))
    fd = np.flatnonzero(free_dist)
    ni = 4 + len(fd)
    n_intr, n_cam = C * ni, (C - 1) * 6
    x0 = np.zeros(n_intr + n_cam + 6 * len(frames))

    def pack(s: Solution) -> F64:
        x = x0.copy()
        for c in range(C):
            K = s.K[c]
            x[c * ni : (c + 1) * ni] = [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *np.ravel(s.dist[c])[fd]]
        if C > 1:
            x[n_intr : n_intr + n_cam] = np.hstack([s.rvec[1:], s.tvec[1:]]).ravel()
        x[n_intr + n_cam :] = np.hstack([s.frame_rvec[frames], s.frame_tvec[frames]]).ravel()
        return x

    def unpack(x: F64) -> Solution:
        Ks, ds = [], []
        for c in range(C):
            p = x[c * ni : (c + 1) * ni]
            Ks.append(np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1.0]]))
            d = np.array(np.ravel(sol.dist[c])[:5], float)
            d[fd] = p[4:]
            ds.append(d)
        ext = x[n_intr : n_intr + n_cam].reshape(-1, 6)
        fp = x[n_intr + n_cam :].reshape(-1, 6)
        fr = np.full((obs.n_frames, 3), np.nan)
        ft = np.full((obs.n_frames, 3), np.nan)
        fr[frames], ft[frames] = fp[:, :3], fp[:, 3:]
        return Solution(Ks, ds, np.vstack([np.zeros(3), ext[:, :3]]), np.vstack([np.zeros(3), ext[:, 3:]]), fr, ft)

    def fun(x: F64) -> F64:
        return reprojection(unpack(x), points, obs).ravel()

    # analytic Jacobian view by view: projectPoints' derivatives chained through composeRT
    order = np.lexsort((obs.frame, obs.cam))
    cuts = np.flatnonzero(np.diff(obs.cam[order] * obs.n_frames + obs.frame[order])) + 1
    groups = np.split(order, cuts)
    rows_l, cols_l = [], []
    for g in groups:
        c, f = int(obs.cam[g[0]]), int(obs.frame[g[0]])
        cols = list(range(c * ni, (c + 1) * ni))
        if c > 0:
            cols += list(range(n_intr + (c - 1) * 6, n_intr + c * 6))
        cols += list(range(n_intr + n_cam + fidx[f] * 6, n_intr + n_cam + fidx[f] * 6 + 6))
        rr = np.stack([2 * g, 2 * g + 1], 1).ravel()
        rows_l.append(np.repeat(rr, len(cols)))
        cols_l.append(np.tile(cols, len(rr)))
    J_rows, J_cols = np.concatenate(rows_l), np.concatenate(cols_l)
    M = len(obs.cam)

    def jac(x: F64) -> csr_matrix:
        s = unpack(x)
        vals = []
        for g in groups:
            c, f = int(obs.cam[g[0]]), int(obs.frame[g[0]])
            r3, t3, dr3dr1, _, dr3dr2, _, _, dt3dt1, dt3dr2, dt3dt2 = cv2.composeRT(
                s.frame_rvec[f], s.frame_tvec[f], s.rvec[c], s.tvec[c]
            )
            _, J = cv2.projectPoints(points[obs.pt[g]].reshape(-1, 1, 3), r3, t3, s.K[c], s.dist[c])
            Jr, Jt, Jf, Jc, Jd = J[:, 0:3], J[:, 3:6], J[:, 6:8], J[:, 8:10], J[:, 10:15]
            blocks = [Jf, Jc, Jd[:, fd]]
            if c > 0:
                blocks += [Jr @ dr3dr2 + Jt @ dt3dr2, Jt @ dt3dt2]
            blocks += [Jr @ dr3dr1, Jt @ dt3dt1]
            vals.append(np.hstack(blocks).ravel())
        return csr_matrix((np.concatenate(vals), (J_rows, J_cols)), shape=(2 * M, len(x0)))

    t0 = time.perf_counter()
    x, res, nit, status = _levenberg_marquardt(fun, jac, pack(sol), max_iter=max_iter)
    out = unpack(x)
    J = jac(x)
    A = (J.T @ J).toarray()
    dof = max(1, len(res) - len(x))
    sigma2 = float(res @ res) / dof
    try:
        cov: F64 | None = np.linalg.inv(A) * sigma2
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))  # type: ignore[arg-type]
    except np.linalg.LinAlgError:
        cov, sd = None, np.full(len(x), np.inf)
    names = ["fx", "fy", "cx", "cy"] + [DIST_NAMES[i] for i in fd]
    unc: list[dict[str, Any]] = []
    for c in range(C):
        u: dict[str, Any] = dict(zip(names, sd[c * ni : (c + 1) * ni].tolist(), strict=True))
        if c > 0 and cov is not None:
            idx = np.arange(n_intr + (c - 1) * 6, n_intr + c * 6)
            p0 = x[idx]
            u["rotation_deg"] = float(np.degrees(np.linalg.norm(sd[idx[:3]])))

            def centre(p: F64) -> F64:
                return np.asarray(-cv2.Rodrigues(p[:3])[0].T @ p[3:], dtype=np.float64)

            eye = np.eye(6)
            Jc_ = np.stack([(centre(p0 + 1e-7 * eye[k]) - centre(p0 - 1e-7 * eye[k])) / 2e-7 for k in range(6)], 1)
            u["centre"] = float(np.sqrt(np.max(np.diag(Jc_ @ cov[np.ix_(idx, idx)] @ Jc_.T))))
        unc.append(u)
    out.rms = rms(res.reshape(-1, 2))
    out.info = {
        "seconds": time.perf_counter() - t0,
        "iterations": nit,
        "status": status,
        "sigma_px": float(np.sqrt(sigma2)),
        "uncertainty": unc,
    }
    return out


def _reject(
    vrms: F64, active: NDArray[np.bool_], factor: float, max_fraction: float = 0.1, min_views: int = 3
) -> NDArray[np.bool_]:
    """Views above ``factor`` x the median of the active views, gradually: at most max(2, 10 %) per round,
    worst first, never leaving a camera below ``min_views`` (losing most views means a failed fit, which
    the diagnosis reports, not outliers)."""
    med = float(np.nanmedian(vrms[active]))
    cand = active & (vrms > factor * med)
    bad = np.zeros_like(active)
    if not cand.any():
        return bad
    cs, fs = np.nonzero(cand)
    order = np.argsort(-vrms[cs, fs])
    cap = max(2, int(max_fraction * active.sum()))
    left = active.sum(1)
    for i in order[:cap]:
        c, f = cs[i], fs[i]
        if left[c] - 1 >= min_views:
            bad[c, f] = True
            left[c] -= 1
    return bad


def _cv_message(exc: cv2.error) -> str:
    text = str(exc).strip().splitlines()[-1] if str(exc).strip() else "OpenCV error"
    return text.split(") ", 1)[-1] if ") " in text else text


@dataclass
class Fit:
    solution: Solution
    active: NDArray[np.bool_]  # (cameras, frames): views used
    usable: NDArray[np.bool_]  # views with enough corners
    history: list[dict[str, Any]]
    view_rms: F64
    corner_ok: NDArray[np.bool_]  # per observation: False for single corners rejected as mis-detected


def solve(
    points: F64,
    obs: Observations,
    sizes: list[tuple[int, int]],
    names: list[str],
    model: str = "k1k2",
    factor: float = 2.5,
    max_rounds: int = 10,
    min_corners: int = 6,
    log: Callable[[str], None] | None = None,
) -> Fit:
    """Initial solution, bundle adjustment and rejection of outlier views; raises CalibrationError naming
    the camera when the take cannot constrain a solution at all."""
    free_dist, flags = MODELS[model]
    say = log or (lambda _msg: None)
    usable = obs.views() >= min_corners
    for c, n in enumerate(names):
        if not usable[c].any():
            raise CalibrationError(f"camera {n} sees the board in no usable view: hold the board in {n}'s view")
    history: list[dict[str, Any]] = []
    problem = None
    try:
        init = opencv_init(points, obs, sizes, flags)
        if not (np.isfinite(init.rms) and init.rms < 10):
            problem = f"RMS {init.rms:.3g} px"
    except cv2.error as exc:
        problem = _cv_message(exc)
    if problem is None:
        history.append({"step": "calibrateMultiviewExtended", "rms_px": init.rms, "seconds": init.info["seconds"]})
        say(f"initial solution (calibrateMultiviewExtended): RMS {init.rms:.4f} px")
    else:
        t0 = time.perf_counter()
        init = own_init(points, obs, sizes, flags, names, min_corners)
        history.append({"step": "calibrateMultiviewExtended could not run", "error": problem})
        history.append({"step": "per-camera initial solution", "seconds": time.perf_counter() - t0})
        say(f"calibrateMultiviewExtended could not run ({problem}); per-camera initial solution instead")
    sol = init
    active = usable.copy()
    corner_ok = np.ones(len(obs.cam), bool)  # single corners far off (a mis-refined corner), dropped
    _fill_frame_poses(points, obs, sol, active)
    vr = np.full(usable.shape, np.nan)

    def used() -> NDArray[np.bool_]:
        return np.asarray(active[obs.cam, obs.frame] & corner_ok)

    for rnd in range(max_rounds):
        sol = bundle_adjust(points, obs.subset(used()), sol, free_dist)
        res = reprojection(sol, points, obs)
        err = np.hypot(res[:, 0], res[:, 1])
        vr = _view_rms_masked(res, obs, corner_ok)
        bad = _reject(vr, active, factor)
        med_corner = float(np.median(err[used()]))
        bad_corners = used() & ~bad[obs.cam, obs.frame] & (err > max(CORNER_FACTOR * med_corner, CORNER_MIN_PX))
        rejected = [(names[c], int(f), float(vr[c, f])) for c, f in zip(*np.nonzero(bad), strict=True)]
        history.append(
            {
                "step": f"bundle adjustment {rnd + 1}",
                "rms_px": sol.rms,
                "seconds": sol.info["seconds"],
                "median_view_rms_px": float(np.nanmedian(vr[active])),
                "rejected": rejected,
                "rejected_corners": int(bad_corners.sum()),
            }
        )
        say(
            f"bundle adjustment {rnd + 1}: RMS {sol.rms:.4f} px"
            + (f", rejecting {len(rejected)} views" if rejected else "")
            + (f", {int(bad_corners.sum())} single corners" if bad_corners.any() else "")
        )
        if not bad.any() and not bad_corners.any():
            break
        active &= ~bad
        corner_ok &= ~bad_corners
    rejected_views = usable & ~active
    if rejected_views.any():  # views rejected while the fit was still poor may fit the final solution
        for f in np.flatnonzero(rejected_views.any(0)):
            if not active[:, f].any():
                sol.frame_rvec[f] = np.nan
        _fill_frame_poses(points, obs, sol, usable)
        vr = _view_rms_masked(reprojection(sol, points, obs), obs, corner_ok)
        back = rejected_views & (vr <= factor * float(np.nanmedian(vr[active])))
        if back.any():
            active |= back
            sol = bundle_adjust(points, obs.subset(used()), sol, free_dist)
            vr = _view_rms_masked(reprojection(sol, points, obs), obs, corner_ok)
            history.append(
                {
                    "step": "re-admission",
                    "readmitted": int(back.sum()),
                    "rms_px": sol.rms,
                    "seconds": sol.info["seconds"],
                }
            )
            say(f"re-admitted {int(back.sum())} views that fit the final solution: RMS {sol.rms:.4f} px")
    if not np.all(np.isfinite(sol.rvec)) or not np.isfinite(sol.rms):
        raise CalibrationError(
            "the calibration did not converge to finite values (see the diagnosis for what to shoot)"
        )
    return Fit(sol, active, usable, history, vr, corner_ok)
