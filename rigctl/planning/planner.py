"""Equations (1) and (2) of the paper as pure, vectorised functions.

Every function takes scalars or numpy arrays (broadcast against each other) in SI units and returns
float64 arrays. Inputs are checked before any arithmetic: zero, negative or NaN values, and a far
distance nearer than the near one, raise :class:`~rigctl.errors.ParameterError` naming the parameter,
so no result ever becomes NaN or infinity silently. A far distance of ``inf`` (background at infinity)
is allowed wherever a far distance is taken, and ``near == far`` gives zero parallax.

Equation (1): u = C0 * Mx / Mz with C0 = f / s_p (focal length in pixels).
Equation (2): d = C0 * dx * (1/M_Fz - 1/M_Bz), the parallax between the foremost and backmost points
seen by two cameras ``dx`` apart.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rigctl.errors import ParameterError

Array = NDArray[np.float64]

# distances a plan or a clipping range can mean: 1 mm from the lens to 1,000 km (beyond it, say inf)
NEAREST_M, FARTHEST_M = 1e-3, 1e6


def check_distances(
    near_m: float | None,
    far_m: float | None,
    depth_m: float | None,
    names: tuple[str, str, str] = ("near", "far", "subject depth"),
) -> None:
    """Distances a camera can be planned for, as ``usd`` holds its clipping range: 1 mm to 1,000 km (``far``
    inf for a background at infinity); outside them the plan is numbers without a meaning (hundreds of
    digits). ``names``: how the caller's user gave near, far and the subject depth (``rigctl plan``'s options,
    the shoot UI's fields)."""
    for name, value in ((names[0], near_m), (names[1], far_m)):
        if value is not None and not math.isinf(value) and not NEAREST_M <= value <= FARTHEST_M:
            raise ParameterError(
                f"{name} {value:g} m: a plan's distances run from {NEAREST_M:g} m to {FARTHEST_M:g} m"
                + (" (inf for a background at infinity)" if name == names[1] else "")
            )
    if depth_m is not None and depth_m > FARTHEST_M:
        raise ParameterError(f"{names[2]} {depth_m:g} m: at most {FARTHEST_M:g} m")


def check_derived_near(near_m: float, given: str, instead: str) -> None:
    """A near side the plan derived (solved from the subject depth, or far minus it) closer than 1 mm to the
    lens: ``given`` says from what, ``instead`` what to give instead."""
    if near_m < NEAREST_M:
        raise ParameterError(
            f"{given}: the subject's near side would be {near_m:.3g} m from the lens, under "
            f"{NEAREST_M * 1e3:g} mm: no shot to plan ({instead})"
        )
    if near_m > FARTHEST_M:  # a budget of 1e-300 solved near = far = 4.8e149 m, the subject's depth lost
        raise ParameterError(
            f"{given}: the subject's near side would be {near_m:.3g} m from the lens, beyond "
            f"{FARTHEST_M / 1e3:,.0f} km: no shot to plan (a larger budget)"
        )


def checked(name: str, value: ArrayLike, *, allow_inf: bool = False, allow_zero: bool = False) -> Array:
    """``value`` as float64, refusing NaN, negative, zero (unless allowed) and infinity (unless allowed)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}") from None
    # one comparison each: NaN fails every comparison, so it is caught with the sign
    ok = (arr >= 0) if allow_zero else (arr > 0)
    if not allow_inf:
        ok &= arr < np.inf
    if not np.all(ok):
        bad = ~ok
        first = float(arr[bad].flat[0]) if arr.ndim else float(arr.item())
        need = "a positive" if not allow_zero else "a non-negative"
        need += " number" if allow_inf else " finite number"
        where = "" if arr.ndim == 0 else f" (first bad value at index {int(np.flatnonzero(bad)[0])})"
        raise ParameterError(f"{name} must be {need}, got {first!r}{where}")
    return arr


def checked_near_far(near_m: ArrayLike, far_m: ArrayLike) -> tuple[Array, Array]:
    near = checked("near_m", near_m)
    far = checked("far_m", far_m, allow_inf=True)
    below = far < near
    if np.any(below):
        n, f = np.broadcast_arrays(near, far)
        i = int(np.flatnonzero(np.broadcast_to(below, n.shape))[0])
        raise ParameterError(
            f"far_m must be >= near_m, got far_m={float(f.flat[i])!r} < near_m={float(n.flat[i])!r}"
            + ("" if n.ndim == 0 else f" (index {i})")
        )
    return near, far


def c0_px(focal_length_m: ArrayLike, pixel_pitch_m: ArrayLike) -> Array:
    """C0 = f / s_p of equation (1): the focal length expressed in pixels."""
    return checked("focal_length_m", focal_length_m) / checked("pixel_pitch_m", pixel_pitch_m)


def image_x_px(c0: ArrayLike, x_m: ArrayLike, z_m: ArrayLike) -> Array:
    """Equation (1): horizontal image coordinate (from the principal point) of a point at (x, z)."""
    x = np.asarray(x_m, dtype=np.float64)
    if np.any(~np.isfinite(x)):
        raise ParameterError(f"x_m must be finite, got {x!r}")
    return checked("c0_px", c0) * x / checked("z_m", z_m)


def disparity_px(c0: ArrayLike, baseline_m: ArrayLike, distance_m: ArrayLike) -> Array:
    """Disparity of a point at ``distance_m`` between two cameras ``baseline_m`` apart (0 at infinity)."""
    return (
        checked("c0_px", c0)
        * checked("baseline_m", baseline_m, allow_zero=True)
        / checked("distance_m", distance_m, allow_inf=True)
    )


def parallax_px(c0: ArrayLike, baseline_m: ArrayLike, near_m: ArrayLike, far_m: ArrayLike) -> Array:
    """Equation (2): total parallax between the nearest and farthest point, in pixels.

    Written as C0 * dx * (1/near - 1/far) rather than with the product of distances, so a far distance
    of infinity is exact and ``near == far`` gives exactly zero.
    """
    c0 = checked("c0_px", c0)
    b = checked("baseline_m", baseline_m, allow_zero=True)
    near, far = checked_near_far(near_m, far_m)
    # 1/near - 1/far as (far - near) / near / far: no cancellation when near ~ far (far - near is exact
    # there), no overflow of near * far, and 1/near exactly when far is infinite.
    finite = np.isfinite(far)
    safe_far = np.where(finite, far, 1.0)
    span = np.where(finite, (safe_far - near) / near / safe_far, 1.0 / near)
    return c0 * b * span


def subject_parallax_px(c0: ArrayLike, baseline_m: ArrayLike, near_m: ArrayLike, subject_depth_m: ArrayLike) -> Array:
    """Equation (2) for a subject ``subject_depth_m`` deep whose front is at ``near_m``.

    C0 * dx * D / (near * (near + D)): exact for any depth, where forming far = near + D first would
    lose a thin subject's depth to rounding.
    """
    c0 = checked("c0_px", c0)
    b = checked("baseline_m", baseline_m, allow_zero=True)
    near = checked("near_m", near_m)
    depth = checked("subject_depth_m", subject_depth_m, allow_inf=True, allow_zero=True)
    finite = np.isfinite(depth)
    d = np.where(finite, depth, 0.0)
    return c0 * b * np.where(finite, d / near / (near + d), 1.0 / near)


def min_near_m(c0: ArrayLike, baseline_m: ArrayLike, subject_depth_m: ArrayLike, max_parallax_px: ArrayLike) -> Array:
    """The nearest distance at which a subject ``subject_depth_m`` deep stays within the parallax budget.

    Solves near^2 + D*near - a*D = 0 with a = C0 * dx / d_max (equation (2) with far = near + D).
    The textbook root (-D + sqrt(D^2 + 4aD)) / 2 cancels catastrophically when D >> a; this form,
    2a*sqrt(D) / (sqrt(D) + sqrt(D + 4a)), has no subtraction, tends to 0 as D -> 0 (continuously, like
    sqrt(aD)) and to ``a`` as D -> infinity (the background at infinity).
    """
    c0 = checked("c0_px", c0)
    b = checked("baseline_m", baseline_m)
    depth = checked("subject_depth_m", subject_depth_m, allow_inf=True, allow_zero=True)
    d_max = checked("max_parallax_px", max_parallax_px)
    a = c0 * b / d_max
    return near_for_scale(a, depth)


def near_for_scale(a: ArrayLike, depth: ArrayLike) -> Array:
    """Positive root of near^2 + D*near - a*D = 0, cancellation-free, exact at D = 0 and D = inf."""
    a, depth = np.broadcast_arrays(a, depth)
    finite = np.isfinite(depth)
    d = np.where(finite, depth, 0.0)
    root = np.sqrt(d)
    with np.errstate(invalid="ignore", divide="ignore"):
        near = np.where(d > 0, 2.0 * a * root / (root + np.sqrt(d + 4.0 * a)), 0.0)
    out: Array = np.where(finite, near, a)
    if np.any(~np.isfinite(out)):
        raise ParameterError("min near distance overflowed: the rig and subject are outside double range")
    return out


def max_spacing_m(c0: ArrayLike, near_m: ArrayLike, far_m: ArrayLike, max_parallax_px: ArrayLike) -> Array:
    """The widest camera spacing that keeps the parallax of [near, far] within ``max_parallax_px``.

    With ``max_parallax_px = 1`` this is the plenoptic sampling limit (Chai et al. 2000). When
    near == far there is no parallax and no limit: the result is ``inf`` by definition, and callers
    report it as unbounded.
    """
    c0 = checked("c0_px", c0)
    d_max = checked("max_parallax_px", max_parallax_px)
    per_metre = parallax_px(c0, 1.0, near_m, far_m)
    with np.errstate(divide="ignore"):
        return np.where(per_metre > 0, d_max / np.where(per_metre > 0, per_metre, 1.0), np.inf)


def disparity_range_px(
    c0: ArrayLike, spacing_x_m: ArrayLike, near_m: ArrayLike, far_m: ArrayLike, margin_px: float = 0.0
) -> tuple[Array, Array]:
    """The disparity search range (for the horizontal spacing) that covers every point in [near, far].

    Returned as (min, max) in pixels, widened by ``margin_px`` on both sides and never below zero
    unless the margin asks for it.
    """
    near, far = checked_near_far(near_m, far_m)
    d_max = disparity_px(c0, spacing_x_m, near)
    d_min = disparity_px(c0, spacing_x_m, far)
    return d_min - margin_px, d_max + margin_px


def check_plan_distances(near_m: float, far_m: float) -> None:
    """Refuse a plan whose nearest distance is not positive and below the farthest (``inf`` allowed), in the
    words of the options that give them: what :func:`search_range_px` needs, checkable before any take is read."""
    if not (near_m > 0 and far_m > near_m):
        raise ParameterError(f"--near must be positive and below --far, got {near_m} and {far_m}")


def search_range_px(
    focal_px: float, spacing_m: float, near_m: float, far_m: float, margin_px: float = 0.0, doffs_px: float = 0.0
) -> tuple[float, float]:
    """The disparity search range of a rectified grid (focal length in pixels, horizontal spacing) for a
    subject between ``near_m`` and ``far_m`` (``inf`` allowed), less the grid's ``doffs_px`` and widened by
    ``margin_px`` on both sides: the one conversion from a plan's distances to a range of disparities."""
    check_plan_distances(near_m, far_m)
    with np.errstate(over="ignore"):  # overflow is refused just below, in one line
        lo, hi = disparity_range_px(focal_px, spacing_m, near_m, far_m)
    if not math.isfinite(float(hi)):
        raise ParameterError(f"--near {near_m} m is too close to plan: its disparity is beyond any number")
    return float(lo) - doffs_px - margin_px, float(hi) - doffs_px + margin_px


def depth_error_m(
    focal_px: ArrayLike, baseline_m: ArrayLike, distance_m: ArrayLike, disparity_error_px: ArrayLike
) -> Array:
    """First-order depth error dZ = Z^2 * dd / (B * f) for a disparity error ``dd`` at distance Z."""
    f = checked("focal_px", focal_px)
    b = checked("baseline_m", baseline_m)
    z = checked("distance_m", distance_m)
    dd = checked("disparity_error_px", disparity_error_px, allow_zero=True)
    with np.errstate(over="ignore"):  # beyond double range (Z ~ 1e154 m) is inf: reports show it as such
        return z * (z * dd / (b * f))


def field_of_view_deg(sensor_extent_m: ArrayLike, focal_length_m: ArrayLike) -> Array:
    """Full angle of view across a sensor extent (width or height) for a rectilinear lens."""
    s = checked("sensor_extent_m", sensor_extent_m)
    f = checked("focal_length_m", focal_length_m)
    return np.degrees(2.0 * np.arctan2(s, 2.0 * f))


def view_extent_m(sensor_extent_m: ArrayLike, focal_length_m: ArrayLike, distance_m: ArrayLike) -> Array:
    """Width (or height) of the plane at ``distance_m`` that one camera sees."""
    s = checked("sensor_extent_m", sensor_extent_m)
    f = checked("focal_length_m", focal_length_m)
    return s * checked("distance_m", distance_m) / f


def fits_every_view(
    subject_extent_m: ArrayLike, array_extent_m: ArrayLike, view_extent: ArrayLike
) -> NDArray[np.bool_]:
    """Whether a subject centred on the array fits in every camera's view of its plane.

    Cameras at the ends of the array (``array_extent_m`` apart, parallel optical axes) each see
    ``view_extent`` centred on themselves; the subject fits when half the array extent plus half the
    subject's extent stays within half the view.
    """
    w = checked("subject_extent_m", subject_extent_m, allow_zero=True)
    a = checked("array_extent_m", array_extent_m, allow_zero=True)
    v = checked("view_extent", view_extent)
    return np.asarray(a / 2.0 + w / 2.0 <= v / 2.0)
