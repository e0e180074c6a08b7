"""The joint calibration's initial solution: OpenCV 5's ``calibrateMultiviewExtended`` on the views that show
the whole board, or, when that cannot run, per-camera ``calibrateCamera`` chained over a spanning tree; and the
board poses either left out, by solvePnP."""

from __future__ import annotations

import time

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.calib.detect import Observations
from rigctl.calib.solution import F64, FitInfo, Solution, chordal_mean
from rigctl.errors import CalibrationError


def cv_message(exc: cv2.error) -> str:
    """OpenCV's error without its source location: the line a user can read."""
    text = str(exc).strip().splitlines()[-1] if str(exc).strip() else "OpenCV error"
    return text.split(") ", 1)[-1] if ") " in text else text


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
    err, Ks, ds, Rs, Ts, _pairs, rv0, tv0, _ = out
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
        FitInfo(seconds=time.perf_counter() - t0, init="calibrateMultiviewExtended"),
    )


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
            raise CalibrationError(f"camera {names[c]}: OpenCV could not calibrate it: {cv_message(exc)}") from None
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
        Rab = chordal_mean(Rs)
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
        info=FitInfo(init="per-camera calibrateCamera + spanning tree"),
    )


def fill_frame_poses(points: F64, obs: Observations, sol: Solution, active: NDArray[np.bool_]) -> None:
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
