"""A plan as the crew reads it: :func:`format_plan`, the text report of :func:`rigctl.planning.report.plan_rig`
(distances, the per-pair-class budget table, the disparity range, what fails). Numbers are bounded in width;
the JSON (:meth:`Plan.as_json`) keeps them whole."""

from __future__ import annotations

import math

from rigctl.planning.report import DEPTH_ERROR_AT_PX, PairPlan, Plan
from rigctl.rig import Rig


def _pair_class(p: PairPlan, rig: Rig) -> str:
    sx, sy = rig.spacing_m
    i, j = round(p.dx_m / sx), round(p.dy_m / sy)
    if j == 0:
        kind = "horizontal"
    elif i == 0:
        kind = "vertical"
    else:
        kind = "diagonal"
    return f"{kind} {i}c {j}r"


FIXED_BELOW = 1e9  # a number of the text report in fixed point below this, in 4 significant digits from it


def _num(value: float, decimals: int) -> str:
    """``value`` with ``decimals`` decimals, as the report's columns show it; from a billion up (a plan at extreme
    distances, where fixed point printed hundreds of digits) 4 significant digits with an exponent."""
    if math.isfinite(value) and abs(value) >= FIXED_BELOW:
        return f"{value:.4g}"
    return f"{value:.{decimals}f}"


def _m(value: float) -> str:
    """A distance of the report's header in millimetres' precision, or, under half a millimetre, in 3 significant
    digits (a subject 1 micrometre deep was "0.000 m")."""
    return f"{value:.3g}" if 0 < abs(value) < 5e-4 else _num(value, 3)


def _col(text: str, width: int) -> str:
    """``text`` right-aligned in a column of ``width``, a space before it however long it is."""
    return " " + text.rjust(width - 1)


def _mm(value: float) -> str:
    return f"{_num(value, 2)} mm" if math.isfinite(value) else "beyond double range"


def format_plan(plan: Plan, rig: Rig) -> str:
    """A readable report: distances, per-pair-class budget table, disparity range, and what fails. Numbers are
    bounded in width (:func:`_num`); the JSON (:meth:`Plan.as_json`) keeps them whole."""
    far = "infinity" if math.isinf(plan.far_m) else f"{_m(plan.far_m)} m"
    lines = [
        f"rig {plan.rig}: {plan.width_px}x{plan.height_px} px, C0 = {_num(plan.c0_px, 1)} px "
        f"(f / s_p), budget {plan.budget_fraction * 100:.2f} % per pair",
        f"near {_m(plan.near_m)} m"
        f"{'  (solved for the ' + plan.reference_pair + ' pair)' if plan.solved_near else ''}"
        f", far {far}, subject depth "
        + ("infinite" if math.isinf(plan.subject_depth_m) else f"{_m(plan.subject_depth_m)} m"),
        f"every pair within budget from {_m(plan.near_m_all_pairs)} m",
        "",
        f"{'pair class':<16}{'pairs':>6}{'baseline mm':>13}{'parallax px':>13}{'% width':>9}{'% height':>10}"
        f"{'min near m':>12}  budget",
    ]
    classes: dict[str, list[PairPlan]] = {}
    for p in plan.pairs:
        classes.setdefault(_pair_class(p, rig), []).append(p)
    for label, group in sorted(classes.items(), key=lambda kv: kv[1][0].baseline_m):
        p = group[0]
        ok = all(q.within_budget for q in group)
        lines.append(
            f"{label:<16}{sum(q.same_offset_pairs for q in group):>6}{_col(_num(p.baseline_m * 1e3, 1), 13)}"
            f"{_col(_num(p.parallax_px, 1), 13)}{_col(_num(p.fraction_of_width * 100, 2), 9)}"
            f"{_col(_num(p.fraction_of_height * 100, 2), 10)}{_col(_num(p.min_near_m, 3), 12)}  "
            + ("ok" if ok else "OVER")
        )
    lines += [
        "",
        f"disparity search range (horizontal spacing): {_num(plan.disparity_min_px, 0)} to "
        f"{_num(plan.disparity_max_px, 0)} px",
        f"depth error at {DEPTH_ERROR_AT_PX} px disparity error: {_mm(plan.depth_error_near_mm)} at near"
        + ("" if plan.depth_error_far_mm is None else f", {_mm(plan.depth_error_far_mm)} at far"),
        "max horizontal spacing for this range: "
        + ("unbounded" if math.isinf(plan.max_spacing_x_m) else f"{_num(plan.max_spacing_x_m * 1e3, 1)} mm"),
        f"field of view {plan.fov_deg[0]:.1f} x {plan.fov_deg[1]:.1f} deg; one camera sees "
        f"{_num(plan.view_at_near_m[0], 2)} x {_num(plan.view_at_near_m[1], 2)} m at near",
    ]
    for axis, ok in plan.subject_fits.items():
        lines.append(f"subject {axis} fits every camera's view at near: {'yes' if ok else 'NO'}")
    over = plan.over_budget
    if over:
        lines.append(
            f"{plan.over_budget_count} of {plan.pair_count} pairs exceed the budget: "
            + ", ".join(p.name for p in over[:6])
            + (" ..." if len(over) > 6 else "")
        )
    else:
        lines.append(f"all {plan.pair_count} pairs within budget")
    return "\n".join(lines)
