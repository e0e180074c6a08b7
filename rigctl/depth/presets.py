"""The depth presets (``rigctl depth --preset``): which engine runs, which views it matches with, how many it
keeps per pixel, its window and its smoothing. ``best`` (the default) runs the cost-volume engine at every
disparity range, the semi-global pairs a second candidate per pixel; only a camera with fewer than three other
views goes to the ``pairs`` engine (``volume_engine.py``); ``fast`` and ``balanced`` run the plane sweep
(``sweep.py``); ``pairs`` runs OpenCV's semi-global matcher per pair, fused by every view (``pair_fusion.py``)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Preset:
    name: str
    views: str  # "horizontal": left and right neighbours; "neighbours": the 8 around; "all": every camera
    keep: float  # share of views kept per pixel (the best ones); 0: the best side (left, right, above, below)
    window: int  # aggregation window (full resolution, pixels)
    refine: bool  # full-resolution refinement (else: half resolution upsampled)
    radius: int = 2  # refinement search radius around the coarse result, px
    cross_check: bool = False
    median: int = 0  # median filter of the result (0: none)
    sgm: tuple[float, float] | None = None  # semi-global smoothing at half resolution: (P1, P2) penalties
    sgm_fine: tuple[float, float] | None = None  # the same over the full-resolution refinement candidates
    engine: str = "sweep"  # "sweep": plane sweep; "pairs": OpenCV SGBM per pair, fused; "volume": costvolume.py
    guided_radius: int = 4  # "volume": guided-filter radius of the cost-volume filtering, px
    guided_eps: float = 1e-4  # "volume": its regularisation (grey levels 0..1, squared)
    with_pairs: bool = True  # "volume": the semi-global pairs are a second candidate, chosen per pixel by cost
    lk_iterations: int = 3  # "volume": Gauss-Newton steps of the continuous refinement along the baselines
    description: str = ""


PRESETS = {
    p.name: p
    for p in (
        Preset("fast", "neighbours", 0.5, 7, refine=False, median=3, description="half resolution, 8 neighbours"),
        Preset(
            "balanced",
            "neighbours",
            0.375,
            3,
            refine=True,
            median=3,
            sgm=(0.05, 0.4),
            sgm_fine=(0.05, 0.3),
            description="coarse-to-fine with semi-global smoothing, 8 neighbours",
        ),
        Preset(
            "best",
            "all",
            0.5,
            3,
            refine=True,
            engine="volume",
            description="multi-view cost volume over the planned range, guided-filter aggregation, best half of "
            "the views per pixel, quarter-pixel sweep, continuous least-squares refinement along the baselines",
        ),
        Preset(
            "pairs",
            "all",
            0.375,
            7,
            refine=True,
            median=5,
            cross_check=True,
            engine="pairs",
            description="OpenCV's semi-global matcher on every neighbouring pair, every camera decides where the "
            "pairs disagree, cross-checked between cameras",
        ),
    )
}
