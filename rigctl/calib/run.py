"""``rigctl calibrate`` end to end: inputs, detection, the joint solve on all frames, a held-out fit for the
rectification residuals, cross-validation on two halves, checks, and (on simulated takes) the error
against the truth. Every stage is timed."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rigctl.board import BoardSpec
from rigctl.calib import metrics
from rigctl.calib.detect import Observations, Target, describe_target, detect, target_points
from rigctl.calib.inputs import CalibrationViews, load_views
from rigctl.calib.report_model import CalibrationReport, CameraReport, RectificationResiduals
from rigctl.calib.solution import F64
from rigctl.calib.solve import Fit, solve
from rigctl.calibration_model import ArrayCalibration, load_calibration, rotation_angle_deg
from rigctl.errors import CalibrationError, RigctlError
from rigctl.rig import rig_from_dict


@dataclass
class Options:
    model: str = "k1k2"
    reject_factor: float = 2.5
    holdout_every: int = 4  # every Nth frame is held out for the residuals (when there are enough frames)
    cross_validate: bool = True
    depth_m: tuple[float, float] | None = None  # board distances for cross-validation (default: from the fit)


@dataclass
class Result:
    calibration: ArrayCalibration
    report: CalibrationReport
    diagnosis: list[str]
    views: CalibrationViews
    obs: Observations
    fit: Fit
    points: Any
    heldout_calibration: ArrayCalibration | None = None
    timings: dict[str, float] = field(default_factory=dict)


def _nominal(views: CalibrationViews) -> tuple[dict[str, F64] | None, str]:
    """Nominal camera centres (rig coordinates, metres) from the take's rig snapshot, when there is one."""
    if not views.rig:
        return None, ""
    try:
        from rigctl.take.reader import TakeReader

        rig = rig_from_dict(
            TakeReader(views.source, skip_damaged=True).manifest.rig, source=str(views.source / "take.yaml")
        )
    except (RigctlError, OSError):
        return None, views.rig
    return {c.name: np.array([c.x_m, c.y_m, 0.0]) for c in rig.cameras}, rig.name


def _fit(
    points: Any, obs: Observations, sizes: list[tuple[int, int]], names: list[str], frames: list[int], opt: Options
) -> Fit:
    keep = np.isin(obs.frame, frames)
    return solve(points, obs.subset(keep), sizes, names, opt.model, opt.reject_factor)


def _good_corners(obs: Observations, fit: Fit) -> Observations:
    """The observations the final fit kept (rejected views and single corners left out)."""
    return obs.subset(fit.active[obs.cam, obs.frame] & fit.corner_ok)


def calibrate(
    source: Path,
    target: Target | None = None,
    options: Options | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    log: Callable[[str], None] | None = None,
) -> Result:
    opt = options or Options()
    target = target or BoardSpec()
    say = log or (lambda _m: None)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    views = load_views(source)
    names = views.names
    sizes = [views.image_size] * len(names)
    obs = detect(views, target, (lambda d, n: progress("detecting corners", d, n)) if progress else None)
    timings["detect_s"] = time.perf_counter() - t0
    points = target_points(target)
    length_unit_m = 1.0 if isinstance(target, BoardSpec) else None
    counts = obs.views()
    say(f"{len(views.frames)} frames x {len(names)} cameras: corners in {int((counts > 0).sum())} views")
    usable = counts >= 6
    early = metrics.diagnose(names, obs, sizes, None, usable, length_unit_m)
    fatal = [d for d in early if "views" in d and ("need" in d)]
    if fatal:
        raise CalibrationError("; ".join(fatal))
    t0 = time.perf_counter()
    try:
        fit = solve(points, obs, sizes, names, opt.model, opt.reject_factor, say=say)
    except CalibrationError as exc:
        hints = "; ".join(early)
        raise CalibrationError(f"{exc}" + (f" ({hints})" if hints else "")) from None
    timings["solve_s"] = time.perf_counter() - t0
    sol = fit.solution
    nominal, rig_name = _nominal(views)
    calib = metrics.to_rig(sol, names, sizes, rig_name or views.rig, nominal, meta={"source": str(source)})
    diagnosis = metrics.diagnose(names, obs, sizes, sol, fit.active, length_unit_m)

    # held-out residuals: fit without every Nth usable frame, rectify with that fit, measure on those frames
    frames_used = [int(f) for f in np.flatnonzero(fit.active.any(0))]
    frames_good = [int(f) for f in np.flatnonzero((fit.active | ~fit.usable).all(0) & fit.active.any(0))]
    heldout_cal = None
    residuals: RectificationResiduals | None = None
    t0 = time.perf_counter()
    if len(names) > 1 and len(frames_used) >= 3 * opt.holdout_every:
        test = frames_good[opt.holdout_every - 1 :: opt.holdout_every]
        train = [f for f in frames_used if f not in test]
        try:
            hfit = _fit(points, obs, sizes, names, train, opt)
            heldout_cal = metrics.to_rig(hfit.solution, names, sizes, calib.rig, nominal)
            residuals = metrics.rectification_residuals(heldout_cal, _good_corners(obs, fit), names, test)
            residuals.held_out_frames = [views.frames[f] for f in test]
        except CalibrationError as exc:
            diagnosis.append(f"held-out check could not run: {exc}")
    timings["heldout_s"] = time.perf_counter() - t0

    # cross-validation: two halves of the frames, disagreement in pixels at the board distances
    cross: dict[str, float] | None = None
    t0 = time.perf_counter()
    if opt.cross_validate and len(frames_used) >= 8:
        depth = opt.depth_m or _board_depths(sol, fit)
        halves = [frames_used[0::2], frames_used[1::2]]
        try:
            a, b = (
                metrics.to_rig(_fit(points, obs, sizes, names, h, opt).solution, names, sizes, calib.rig)
                for h in halves
            )
            cross = metrics.cross_validate(a, b, depth)
        except CalibrationError as exc:
            diagnosis.append(f"cross-validation could not run: {exc}")
    timings["cross_validation_s"] = time.perf_counter() - t0

    truth = None
    if views.truth is not None:
        truth = metrics.compare_to_truth(calib, load_calibration(views.truth))
    report = _report(views, target, obs, fit, calib, nominal, residuals, cross, truth, diagnosis, timings)
    return Result(calib, report, diagnosis, views, obs, fit, points, heldout_cal, timings)


def _board_depths(sol: Any, fit: Fit) -> tuple[float, float]:
    z = sol.frame_tvec[np.isfinite(sol.frame_tvec[:, 2]) & fit.active.any(0), 2]
    return (float(z.min()), float(z.max())) if len(z) else (1.0, 1.0)


def _report(
    views: CalibrationViews,
    target: Target,
    obs: Observations,
    fit: Fit,
    calib: ArrayCalibration,
    nominal: dict[str, F64] | None,
    residuals: RectificationResiduals | None,
    cross: dict[str, float] | None,
    truth: dict[str, dict[str, float]] | None,
    diagnosis: list[str],
    timings: dict[str, float],
) -> CalibrationReport:
    from rigctl.calib.solution import reprojection, rms

    names = views.names
    sol = fit.solution
    res = reprojection(sol, target_points(target), obs)
    used = fit.active[obs.cam, obs.frame] & fit.corner_ok
    centroid = np.mean([calib[n].centre for n in names], axis=0)
    cams: dict[str, CameraReport] = {}
    for c, n in enumerate(names):
        m = (obs.cam == c) & used
        rejected = [views.frames[f] for f in np.flatnonzero(fit.usable[c] & ~fit.active[c])]
        cov, corner_cells = metrics.coverage(obs, c, views.image_size, fit.active)
        cams[n] = CameraReport(
            rms_px=rms(res[m]),
            frames_used=int(fit.active[c].sum()),
            frames_rejected=rejected,
            rotation_vs_common_deg=rotation_angle_deg(calib[n].R),
            coverage=cov,
            corner_cells=corner_cells,
            distortion_monotonic=metrics.distortion_monotonic(sol.K[c], sol.dist[c], views.image_size),
            focal_px=float(sol.K[c][0, 0]),
            uncertainty=sol.info.uncertainty[c].as_dict() if sol.info.uncertainty else {},
            position_vs_nominal_mm=((calib[n].centre - nominal[n]) * 1e3).tolist() if nominal is not None else None,
            position_vs_centroid=(calib[n].centre - centroid).tolist() if nominal is None else None,
            cross_validation_px=cross[n] if cross is not None else None,
            truth=truth[n] if truth is not None else None,
            input_name=views.source_names.get(n) or None,
        )
    rejected_frames = sorted(
        {views.frames[f] for f in np.flatnonzero((fit.usable & ~fit.active).any(0))}, key=lambda s: (len(s), s)
    )
    return CalibrationReport(
        source=str(views.source),
        target=describe_target(target),
        cameras=cams,
        rms_px=sol.rms,
        frames=len(views.frames),
        frames_with_rejected_views=rejected_frames,
        rejected_corners=int((fit.active[obs.cam, obs.frame] & ~fit.corner_ok).sum()),
        rejected_views=[
            (names[c], views.frames[f]) for c, f in zip(*np.nonzero(fit.usable & ~fit.active), strict=True)
        ],
        rectification_residuals=residuals,
        cross_validation_px=cross,
        truth=truth is not None,
        diagnosis=diagnosis,
        history=fit.history,
        timings_s=timings,
    )
