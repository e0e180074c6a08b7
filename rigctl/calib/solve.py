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

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.calib.bundle import bundle_adjust
from rigctl.calib.detect import Observations
from rigctl.calib.initial import cv_message, fill_frame_poses, opencv_init, own_init
from rigctl.calib.solution import F64, Solution, reprojection, view_rms_masked
from rigctl.errors import CalibrationError

log = logging.getLogger(__name__)
MODELS = {
    "k1k2": ((True, True, False, False, False), cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST),
    "k1k2k3": ((True, True, False, False, True), cv2.CALIB_ZERO_TANGENT_DIST),
    "full": ((True, True, True, True, True), 0),
}


CORNER_FACTOR = 5.0  # a single corner this many times the median corner error ...
CORNER_MIN_PX = 0.5  # ... and above this is a mis-detection, not noise


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


@dataclass
class FitStep:
    """One step of the solve, as the calibration report lists it (only what the step measured)."""

    step: str
    rms_px: float | None = None
    seconds: float | None = None
    median_view_rms_px: float | None = None
    rejected: list[tuple[str, int, float]] | None = None  # views: camera, frame, their RMS (px)
    rejected_corners: int | None = None
    readmitted: int | None = None
    error: str | None = None

    def as_dict(self) -> dict[str, str | float | int | list[tuple[str, int, float]]]:
        return {k: v for k, v in vars(self).items() if v is not None}


@dataclass
class Fit:
    solution: Solution
    active: NDArray[np.bool_]  # (cameras, frames): views used
    usable: NDArray[np.bool_]  # views with enough corners
    history: list[FitStep]
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
    say: Callable[[str], None] | None = None,
) -> Fit:
    """Initial solution, bundle adjustment and rejection of outlier views; raises CalibrationError naming
    the camera when the take cannot constrain a solution at all."""
    free_dist, flags = MODELS[model]
    report = say or log.info  # each step, as the caller shows progress (or to this module's log)
    usable = obs.views() >= min_corners
    for c, n in enumerate(names):
        if not usable[c].any():
            raise CalibrationError(f"camera {n} sees the board in no usable view: hold the board in {n}'s view")
    history: list[FitStep] = []
    problem = None
    try:
        init = opencv_init(points, obs, sizes, flags)
        if not (np.isfinite(init.rms) and init.rms < 10):
            problem = f"RMS {init.rms:.3g} px"
    except cv2.error as exc:
        problem = cv_message(exc)
    if problem is None:
        history.append(FitStep("calibrateMultiviewExtended", rms_px=init.rms, seconds=init.info.seconds))
        report(f"initial solution (calibrateMultiviewExtended): RMS {init.rms:.4f} px")
    else:
        t0 = time.perf_counter()
        init = own_init(points, obs, sizes, flags, names, min_corners)
        history.append(FitStep("calibrateMultiviewExtended could not run", error=problem))
        history.append(FitStep("per-camera initial solution", seconds=time.perf_counter() - t0))
        report(f"calibrateMultiviewExtended could not run ({problem}); per-camera initial solution instead")
    sol = init
    active = usable.copy()
    corner_ok = np.ones(len(obs.cam), bool)  # single corners far off (a mis-refined corner), dropped
    fill_frame_poses(points, obs, sol, active)
    vr = np.full(usable.shape, np.nan)

    def used() -> NDArray[np.bool_]:
        return np.asarray(active[obs.cam, obs.frame] & corner_ok)

    for rnd in range(max_rounds):
        sol = bundle_adjust(points, obs.subset(used()), sol, free_dist)
        res = reprojection(sol, points, obs)
        err = np.hypot(res[:, 0], res[:, 1])
        vr = view_rms_masked(res, obs, corner_ok)
        bad = _reject(vr, active, factor)
        med_corner = float(np.median(err[used()]))
        bad_corners = used() & ~bad[obs.cam, obs.frame] & (err > max(CORNER_FACTOR * med_corner, CORNER_MIN_PX))
        rejected = [(names[c], int(f), float(vr[c, f])) for c, f in zip(*np.nonzero(bad), strict=True)]
        history.append(
            FitStep(
                f"bundle adjustment {rnd + 1}",
                rms_px=sol.rms,
                seconds=sol.info.seconds,
                median_view_rms_px=float(np.nanmedian(vr[active])),
                rejected=rejected,
                rejected_corners=int(bad_corners.sum()),
            )
        )
        report(
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
        fill_frame_poses(points, obs, sol, usable)
        vr = view_rms_masked(reprojection(sol, points, obs), obs, corner_ok)
        back = rejected_views & (vr <= factor * float(np.nanmedian(vr[active])))
        if back.any():
            active |= back
            sol = bundle_adjust(points, obs.subset(used()), sol, free_dist)
            vr = view_rms_masked(reprojection(sol, points, obs), obs, corner_ok)
            history.append(
                FitStep("re-admission", readmitted=int(back.sum()), rms_px=sol.rms, seconds=sol.info.seconds)
            )
            report(f"re-admitted {int(back.sum())} views that fit the final solution: RMS {sol.rms:.4f} px")
    if not np.all(np.isfinite(sol.rvec)) or not np.isfinite(sol.rms):
        raise CalibrationError(
            "the calibration did not converge to finite values (see the diagnosis for what to shoot)"
        )
    return Fit(sol, active, usable, history, vr, corner_ok)
