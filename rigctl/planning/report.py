"""The planner applied to a rig: every camera pair against the parallax budget, as data, JSON and a table.

The arithmetic lives in :mod:`rigctl.planning.planner`; this module decides which distances to use (solve the
near distance from a subject depth, or check given near/far), evaluates every pair of the rig in one
vectorised call (the text report is :mod:`rigctl.planning.text`).

Pairs with the same row and column offset see the same parallax, so the arithmetic is done once per offset
(a 64x64 grid has 8.4 million pairs but 8,127 offsets). Every pair is listed while there are at most
:data:`LIST_PAIRS_UP_TO`; beyond that the plan lists one pair per offset with ``same_offset_pairs``.
JSON holds no infinity or NaN at any finite input: a value beyond double range is ``null`` and its key
is listed under ``not_representable``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from itertools import combinations
from typing import Any

import numpy as np

import rigctl.planning.planner as planner
from rigctl.errors import ParameterError
from rigctl.rig import Rig

DEFAULT_SUBJECT_DEPTH_M = 1.0
DEFAULT_BUDGET = 0.04
DEPTH_ERROR_AT_PX = 0.25  # disparity error used for the depth-error readout (a good sub-pixel matcher)
_TOL = 1e-9  # relative slack so a solved near distance is counted within budget
LIST_PAIRS_UP_TO = 10_000  # a 14x14 grid has 9,591 pairs, 15x15 has 12,600


@dataclass(frozen=True)
class PairPlan:
    """One camera pair: its baseline, the parallax of [near, far] it sees, and its own budget."""

    name: str
    baseline_m: float
    dx_m: float
    dy_m: float
    parallax_px: float
    parallax_x_px: float
    parallax_y_px: float
    fraction_of_width: float
    fraction_of_height: float
    within_budget: bool
    min_near_m: float
    same_offset_pairs: int = 1  # pairs of the rig this entry stands for (1 unless the plan is grouped)

    def as_json(self, grouped: bool = False) -> dict[str, Any]:
        out = {
            "name": self.name,
            "baseline_m": self.baseline_m,
            "dx_m": self.dx_m,
            "dy_m": self.dy_m,
            "parallax_px": self.parallax_px,
            "parallax_x_px": self.parallax_x_px,
            "parallax_y_px": self.parallax_y_px,
            "fraction_of_width": self.fraction_of_width,
            "fraction_of_height": self.fraction_of_height,
            "within_budget": self.within_budget,
            "min_near_m": self.min_near_m,
        }
        if grouped:
            out["same_offset_pairs"] = self.same_offset_pairs
        return out


@dataclass(frozen=True)
class Plan:
    """The plan for one shot on one rig."""

    rig: str
    width_px: int
    height_px: int
    c0_px: float
    c0_y_px: float
    near_m: float
    far_m: float
    subject_depth_m: float
    budget_fraction: float
    solved_near: bool
    reference_pair: str
    pairs: list[PairPlan]
    near_m_all_pairs: float
    disparity_min_px: int
    disparity_max_px: int
    max_spacing_x_m: float
    depth_error_near_mm: float
    depth_error_far_mm: float | None
    fov_deg: tuple[float, float]
    view_at_near_m: tuple[float, float]
    subject_fits: dict[str, bool] = field(default_factory=dict)
    pair_count: int = 0
    pairs_grouped: bool = False

    @property
    def over_budget(self) -> list[PairPlan]:
        return [p for p in self.pairs if not p.within_budget]

    @property
    def over_budget_count(self) -> int:
        return sum(p.same_offset_pairs for p in self.over_budget)

    def as_json(self) -> dict[str, Any]:
        far_inf = math.isinf(self.far_m)
        out: dict[str, object] = {
            "rig": self.rig,
            "image_px": [self.width_px, self.height_px],
            "c0_px": self.c0_px,
            "c0_y_px": self.c0_y_px,
            "near_m": self.near_m,
            "far_m": None if far_inf else self.far_m,
            "far_at_infinity": far_inf,
            "subject_depth_m": None if math.isinf(self.subject_depth_m) else self.subject_depth_m,
            "budget_fraction": self.budget_fraction,
            "solved_near": self.solved_near,
            "reference_pair": self.reference_pair,
            "near_m_all_pairs": self.near_m_all_pairs,
            "all_within_budget": not self.over_budget,
            "pair_count": self.pair_count,
            "pairs_grouped": self.pairs_grouped,
            "pairs": [p.as_json(self.pairs_grouped) for p in self.pairs],
            "disparity_range_px": {"min": self.disparity_min_px, "max": self.disparity_max_px},
            "max_spacing_x_m": None if math.isinf(self.max_spacing_x_m) else self.max_spacing_x_m,
            "depth_error_mm": {
                "disparity_error_px": DEPTH_ERROR_AT_PX,
                "at_near": self.depth_error_near_mm,
                "at_far": self.depth_error_far_mm,
            },
            "fov_deg": {"horizontal": self.fov_deg[0], "vertical": self.fov_deg[1]},
            "view_at_near_m": {"width": self.view_at_near_m[0], "height": self.view_at_near_m[1]},
        }
        if self.subject_fits:
            out["subject_fits"] = self.subject_fits
        lost: list[str] = []
        clean: dict[str, object] = _finite_or_none(out, "", lost)
        if lost:
            clean["not_representable"] = lost
        return clean


def _finite_or_none(value: Any, where: str, lost: list[str]) -> Any:
    """``value`` with every infinite or NaN float replaced by None (their keys collected in ``lost``)."""
    if isinstance(value, float) and not math.isfinite(value):
        lost.append(where)
        return None
    if isinstance(value, dict):
        return {k: _finite_or_none(v, f"{where}.{k}" if where else str(k), lost) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite_or_none(v, f"{where}[{i}]", lost) for i, v in enumerate(value)]
    return value


@dataclass(frozen=True)
class _Offsets:
    """Camera pairs grouped by offset: ``rows`` (>= 0) and ``cols`` (>= 0) apart, how many, and the first pair
    of each group in row-major order."""

    rows: np.ndarray
    cols: np.ndarray
    count: np.ndarray
    example: list[str]


def _offset_groups(rig: Rig) -> _Offsets:
    cams = rig.cameras
    n_rows = max(c.row for c in cams) + 1
    n_cols = max(c.col for c in cams) + 1
    order = np.full((n_rows, n_cols), -1, dtype=np.int64)
    names = {}
    for i, cam in enumerate(cams):
        order[cam.row, cam.col] = i
        names[i] = cam.name
    occupied = order >= 0
    groups: dict[tuple[int, int], list[Any]] = {}  # (rows, |cols|) -> [count, (first a, first b)]
    for dr in range(n_rows):
        for dc in range(-(n_cols - 1), n_cols):
            if dr == 0 and dc <= 0:
                continue  # pairs (a, b) with a before b in row-major order
            c0, c1 = max(0, -dc), n_cols - max(0, dc)
            both = occupied[: n_rows - dr, c0:c1] & occupied[dr:, c0 + dc : c1 + dc]
            n = int(np.count_nonzero(both))
            if not n:
                continue
            r, c = divmod(int(np.flatnonzero(both)[0]), c1 - c0)
            first = (int(order[r, c + c0]), int(order[r + dr, c + c0 + dc]))
            entry = groups.setdefault((dr, abs(dc)), [0, first])
            entry[0] += n
            entry[1] = min(entry[1], first)
    keys = sorted(groups, key=lambda k: groups[k][1])
    return _Offsets(
        rows=np.array([k[0] for k in keys], dtype=np.int64),
        cols=np.array([k[1] for k in keys], dtype=np.int64),
        count=np.array([groups[k][0] for k in keys], dtype=np.int64),
        example=[f"{names[groups[k][1][0]]}-{names[groups[k][1][1]]}" for k in keys],
    )


def _reference_index(rig: Rig, groups: _Offsets) -> int:
    """The pair the paper's rule is stated for: adjacent horizontal cameras (else adjacent vertical)."""
    for want in ((0, 1), (1, 0)):
        hit = np.flatnonzero((groups.rows == want[0]) & (groups.cols == want[1]))
        if hit.size:
            return int(hit[0])
    raise ParameterError(f"rig {rig.name} has no camera pair: there is no parallax to plan")


def _every_pair(rig: Rig, groups: _Offsets, per_group: list[PairPlan]) -> list[PairPlan]:
    """Every pair of the rig in ``combinations`` order, each with its group's numbers."""
    at = {(int(r), int(c)): i for i, (r, c) in enumerate(zip(groups.rows, groups.cols, strict=True))}
    return [
        replace(per_group[at[(b.row - a.row, abs(b.col - a.col))]], name=f"{a.name}-{b.name}", same_offset_pairs=1)
        for a, b in combinations(rig.cameras, 2)
    ]


def _pair_scale(rig: Rig, dx: np.ndarray, dy: np.ndarray, budget: float) -> np.ndarray:
    """For each pair, the largest 1/near - 1/far its budget allows (min over the x and y components)."""
    w, h = rig.width_px, rig.height_px
    with np.errstate(divide="ignore"):
        kx = np.where(dx > 0, budget * w / (rig.c0_px * np.where(dx > 0, dx, 1.0)), np.inf)
        ky = np.where(dy > 0, budget * h / (rig.c0_y_px * np.where(dy > 0, dy, 1.0)), np.inf)
    return np.minimum(kx, ky)


def _check_budget(budget: float) -> float:
    b = float(planner.checked("budget_fraction", budget))
    if b > 1:
        raise ParameterError(f"budget_fraction must be a fraction of the image in (0, 1], got {budget!r}")
    return b


def plan_rig(
    rig: Rig,
    *,
    subject_depth_m: float | None = None,
    near_m: float | None = None,
    far_m: float | None = None,
    budget_fraction: float | None = None,
    subject_width_m: float | None = None,
    subject_height_m: float | None = None,
) -> Plan:
    """Plan a shot: with a subject depth alone, solve the near distance; with near/far, check every pair.

    Missing values come from the rig's ``plan:`` section, then from the paper's defaults (subject 1 m
    deep, 4 % budget).
    """
    defaults = rig.model.plan
    if budget_fraction is None:
        budget_fraction = defaults.budget_fraction if defaults else DEFAULT_BUDGET
    budget = _check_budget(budget_fraction)
    if near_m is None and far_m is None and subject_depth_m is None and defaults is not None:
        near_m, far_m, subject_depth_m = defaults.near_m, defaults.far_m, defaults.subject_depth_m
    if subject_depth_m is not None:
        planner.checked("subject_depth_m", subject_depth_m, allow_inf=True, allow_zero=True)

    groups = _offset_groups(rig)
    names = groups.example
    if not names:
        raise ParameterError(f"rig {rig.name} has a single camera: there is no parallax to plan")
    dx = groups.cols * rig.spacing_m[0]
    dy = groups.rows * rig.spacing_m[1]
    ref = _reference_index(rig, groups)
    kmax = _pair_scale(rig, dx, dy, budget)
    depth_for_solve = subject_depth_m if subject_depth_m is not None else DEFAULT_SUBJECT_DEPTH_M

    solved = False
    if near_m is None and far_m is None:
        depth = planner.checked("subject_depth_m", depth_for_solve, allow_inf=True, allow_zero=True)
        near_m = float(planner.near_for_scale(np.asarray(1.0 / kmax[ref]), depth))
        if near_m == 0.0:
            raise ParameterError(
                f"subject_depth_m {float(depth)!r} is a flat subject: it has no parallax at any distance, so "
                "there is no minimum near distance; give --near and --far to check a shot"
            )
        far_m = near_m + float(depth)
        solved = True
    elif near_m is not None and far_m is None:
        if subject_depth_m is None:
            raise ParameterError("near_m given without far_m: give --far or --subject-depth as well")
        far_m = near_m + subject_depth_m
    elif far_m is not None and near_m is None:
        if subject_depth_m is None:
            raise ParameterError("far_m given without near_m: give --near or --subject-depth as well")
        if math.isinf(far_m):
            raise ParameterError("far_m is infinite: give --near, a subject depth cannot be measured from infinity")
        near_m = far_m - subject_depth_m
        if not near_m > 0:
            raise ParameterError(
                f"subject_depth_m {subject_depth_m!r} is not less than far_m {far_m!r}: the subject would "
                "start behind the rig"
            )
    elif subject_depth_m is not None:
        raise ParameterError("give near and far, or a subject depth with one of them, not all three")
    assert near_m is not None and far_m is not None
    near_a, far_a = planner.checked_near_far(near_m, far_m)
    near, far = float(near_a), float(far_a)
    if solved or (subject_depth_m is not None and not math.isinf(far)):
        depth_here = float(depth_for_solve)
    else:
        depth_here = far - near

    c0x, c0y = rig.c0_px, rig.c0_y_px
    with np.errstate(over="ignore"):
        px_x = planner.parallax_px(c0x, dx, near, far)
        px_y = planner.parallax_px(c0y, dy, near, far)
        d_lo, d_hi = planner.disparity_range_px(c0x, rig.spacing_m[0], near, far)
    if not (np.all(np.isfinite(px_x)) and np.all(np.isfinite(px_y)) and np.isfinite(d_hi)):
        raise ParameterError(
            f"near_m {near!r} is so close that the parallax is beyond double range: no camera can see it"
        )
    fx, fy = px_x / rig.width_px, px_y / rig.height_px
    within = (fx <= budget * (1 + _TOL)) & (fy <= budget * (1 + _TOL))
    pair_near = planner.near_for_scale(1.0 / kmax, np.asarray(depth_here))
    pairs = [
        PairPlan(
            name=names[i],
            baseline_m=float(math.hypot(dx[i], dy[i])),
            dx_m=float(dx[i]),
            dy_m=float(dy[i]),
            parallax_px=float(math.hypot(px_x[i], px_y[i])),
            parallax_x_px=float(px_x[i]),
            parallax_y_px=float(px_y[i]),
            fraction_of_width=float(math.hypot(px_x[i], px_y[i]) / rig.width_px),
            fraction_of_height=float(math.hypot(px_x[i], px_y[i]) / rig.height_px),
            within_budget=bool(within[i]),
            min_near_m=float(pair_near[i]),
            same_offset_pairs=int(groups.count[i]),
        )
        for i in range(len(names))
    ]
    pair_count = int(groups.count.sum())
    grouped = pair_count > LIST_PAIRS_UP_TO
    if not grouped:
        pairs = _every_pair(rig, groups, pairs)
    sx = rig.spacing_m[0]
    max_sx = planner.max_spacing_m(c0x, near, far, budget * rig.width_px)
    err_near = planner.depth_error_m(c0x, sx, near, DEPTH_ERROR_AT_PX) * 1e3
    err_far = None if math.isinf(far) else float(planner.depth_error_m(c0x, sx, far, DEPTH_ERROR_AT_PX) * 1e3)
    sensor = rig.model.sensor
    f = rig.focal_length_m
    view_w = float(planner.view_extent_m(sensor.width_mm * 1e-3, f, near))
    view_h = float(planner.view_extent_m(sensor.height_mm * 1e-3, f, near))
    fits: dict[str, bool] = {}
    g = rig.model.grid
    if subject_width_m is not None:
        fits["width"] = bool(planner.fits_every_view(subject_width_m, (g.columns - 1) * sx, view_w))
    if subject_height_m is not None:
        fits["height"] = bool(planner.fits_every_view(subject_height_m, (g.rows - 1) * rig.spacing_m[1], view_h))
    fov = (
        float(planner.field_of_view_deg(sensor.width_mm * 1e-3, f)),
        float(planner.field_of_view_deg(sensor.height_mm * 1e-3, f)),
    )
    return Plan(
        rig=rig.name,
        width_px=rig.width_px,
        height_px=rig.height_px,
        c0_px=c0x,
        c0_y_px=c0y,
        near_m=near,
        far_m=far,
        subject_depth_m=depth_here,
        budget_fraction=budget,
        solved_near=solved,
        reference_pair=names[ref],
        pairs=pairs,
        near_m_all_pairs=float(pair_near.max()),
        disparity_min_px=math.floor(float(d_lo)),
        disparity_max_px=math.ceil(float(d_hi)),
        max_spacing_x_m=float(max_sx),
        depth_error_near_mm=float(err_near),
        depth_error_far_mm=err_far,
        fov_deg=fov,
        view_at_near_m=(view_w, view_h),
        subject_fits=fits,
        pair_count=pair_count,
        pairs_grouped=grouped,
    )
