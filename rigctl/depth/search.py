"""What every depth engine is handed (one camera's search) and what it hands back (its estimate inside the
searched box), with the per-camera statistics that end up in ``report.json``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from typing_extensions import TypedDict  # pydantic validates these (the report) only on Python < 3.12

from rigctl.depth.grid import Grid
from rigctl.depth.presets import Preset

F32 = NDArray[np.float32]


class EstimateStats(TypedDict, total=False):
    """One camera's estimate, as reported (times in seconds, shares 0..1). Engines fill what they measure."""

    camera: str
    preset: str
    engine: str  # the best preset: which engine ran, and why
    views: list[str]  # the other cameras matched with
    note: str  # why there is no estimate, or a fallback taken
    seconds: float
    key_s: float
    keyed_background_share: float
    searched_share: float
    estimated_share_of_subject: float
    bound_hit_pixels: int
    unreliable_pixels: int
    sensor_fixed_pixels: int  # matched unshifted, outside the range: fixed to the sensor (edge.py)
    sensor_fixed_s: float
    filled_from_background_pixels: int
    levels: int  # disparity levels searched
    sgm: bool
    coarse_s: float
    refine_s: float
    coarse_scale: float
    integer_sweep_s: float
    fractional_candidates: int
    fractional_step: float  # px between the fractional sweep's candidates
    fractional_sweep_s: float
    band_scale: float  # the sweep between a quarter-scale one and the full resolution (costvolume.band)
    band_sweep_s: float
    # where the time went (the cost volume: summed over its sweeps) and the work each stage did, in pixels
    # times the disparities evaluated there (issue 24)
    cost_s: float  # the matching cost of every level and candidate
    aggregation_s: float  # its guided-filter aggregation
    candidates_s: float  # the semi-global pairs as a second candidate and the per-pixel choice
    refinement_s: float  # the continuous refinement along the baselines and the outlier clean-up
    integer_sweep_pixel_levels: int
    fractional_sweep_pixel_levels: int
    band_sweep_pixel_levels: int  # at half scale: a quarter of the full resolution's pixels
    pairs_pixel_levels: int  # OpenCV's semi-global matcher, over every pair (its rows or columns x levels)
    refine_pixel_levels: int  # pixels x Gauss-Newton steps
    pairs: int
    pairs_s: float
    conflict_share: float
    select_s: float
    pairs_chosen_share: float
    outliers_replaced: int
    # estimated pixels whose point fewer than three other views see: inside their frame and not behind a
    # nearer surface of the camera's own estimate (the bands at the frame's edges and behind foreground edges)
    fewer_than_3_views_pixels: int
    views_count_s: float  # counting them
    occlusion_order_pixels: int  # seen farther by most other views: given what they see (edge.occlusion_order)
    occlusion_order_removed_pixels: int  # of those, the ones every such view saw as screen: no depth
    occlusion_order_s: float
    cross_check_with: str
    cross_check_failed_pixels: int
    cross_check_s: float
    # temporal stability (temporal.py): shares of the estimated pixels
    temporal_blended_share: float  # still, and agreeing with the previous depth: its running mean
    temporal_kept_share: float  # still, disagreeing, and the previous depth matches as well: kept
    temporal_replaced_share: float  # still, disagreeing, and the new estimate matches clearly better: taken
    temporal_held_share: float  # changed, within the agreement, and the previous depth matches clearly better: kept
    temporal_new_share: float  # the colour changed in a view that sees it (or no previous depth): new estimate
    temporal_agree_px: float  # within this of the previous depth, a new estimate agrees with it
    temporal_noise_sigma: float  # the camera's noise measured from the frame differences (half size), 8-bit levels
    temporal_changed_share: float  # share of the camera's pixels whose colour changed beyond the noise
    temporal_s: float


@dataclass
class BoxEstimate:
    """What an engine found inside the searched box (all arrays box-sized)."""

    disparity: F32
    cost: F32  # the chosen match's aggregated cost (0 perfect, TRUNCATE no match)
    distinct: F32  # 0..1: how clearly the match stands out (or how well the estimates agree)
    texture: F32
    bright: F32
    bound: NDArray[np.bool_]  # the coarse search's best lay at the planned range's edge
    no_view: NDArray[np.bool_]  # no other camera sees the point
    filled: NDArray[np.bool_] | None = None  # no match found: filled from the background side


@dataclass
class SearchJob:
    """One camera's search: the views it matches with, the box searched, the range, the preset."""

    grid: Grid
    ref: str
    moving: list[str]
    box: tuple[int, int, int, int]
    d_range: tuple[float, float]
    keep: int
    preset: Preset
    stats: EstimateStats
    region: NDArray[np.bool_]  # box-sized: the pixels to estimate (the keyed subject)
