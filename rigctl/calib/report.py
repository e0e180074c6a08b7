"""The calibration report: a table for people, and PNG plots (corner coverage per camera, residuals)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rigctl.calib.run import Result
from rigctl.publish import publish_figure


def _f(v: Any, fmt: str = ".3f") -> str:
    return "-" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, fmt)


def format_table(result: Result) -> str:
    rep = result.report
    lines = [f"calibrated {len(rep.cameras)} cameras from {rep.source} ({rep.target})"]
    has_nominal = any(c.position_vs_nominal_mm is not None for c in rep.cameras.values())
    head = [
        "camera",
        "RMS px",
        "views",
        "rejected",
        "vs lattice mm" if has_nominal else "position",
        "rot deg",
        "coverage",
    ]
    if rep.cross_validation_px:
        head.append("x-val px")
    if rep.truth:
        head += ["truth: centre mm", "rot deg", "ray deg"]
    rows = [head]
    for n, c in rep.cameras.items():
        pos = c.position_vs_nominal_mm
        where = (
            f"{np.linalg.norm(pos):.2f}"
            if pos is not None
            else " ".join(f"{v:.3g}" for v in (c.position_vs_centroid or []))
        )
        label = n + (f" ({c.input_name})" if c.input_name else "")
        row = [
            label,
            _f(c.rms_px, ".4f"),
            str(c.frames_used),
            ",".join(c.frames_rejected) or "-",
            where,
            _f(c.rotation_vs_common_deg, ".3f"),
            f"{c.coverage:.0%}",
        ]
        if rep.cross_validation_px:
            row.append(_f(c.cross_validation_px))
        if rep.truth:
            t = c.truth or {}
            row += [_f(t.get("centre_mm")), _f(t.get("rotation_deg"), ".4f"), _f(t.get("ray_deg"), ".4f")]
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    lines += ["  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip() for r in rows]
    lines.append(f"overall RMS {rep.rms_px:.4f} px")
    if rep.rejected_corners:
        lines.append(f"single corners rejected as mis-detected: {rep.rejected_corners}")
    if rep.rejected_views:
        lines.append("rejected views (camera frame): " + ", ".join(f"{c} {f}" for c, f in rep.rejected_views))
    res = rep.rectification_residuals
    if res:
        lines.append(f"rectification residuals on {res.frames} held-out frames (px; raw / net of camera placement):")
        for pooled, label in (
            (res.vertical_between_horizontal_neighbours, "vertical disparity, horizontal neighbours"),
            (res.horizontal_between_vertical_neighbours, "horizontal disparity, vertical neighbours"),
        ):
            raw, net = pooled.raw, pooled.net
            if raw.n:
                lines.append(
                    f"  {label}: RMS {raw.rms:.3f} / {net.rms:.3f}, p95 {raw.p95:.3f} / {net.p95:.3f}, "
                    f"max {raw.max:.3f} / {net.max:.3f} ({raw.n} corners)"
                )
        ratio = res.disparity_ratio
        if ratio:
            lines.append(
                f"  horizontal / vertical disparity {ratio.median:.4f} against dx/dy {ratio.expected_dx_over_dy:.4f}"
            )
    t = rep.timings_s
    lines.append("time: " + ", ".join(f"{k.removesuffix('_s').replace('_', ' ')} {v:.1f} s" for k, v in t.items()))
    return "\n".join(lines)


def write_plots(result: Result, stem: Path) -> list[Path]:
    """``<stem>_coverage.png`` (detected corners per camera, used and rejected) and ``<stem>_residuals.png``
    (reprojection residual vectors, and held-out rectification residuals when measured)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rigctl.calib.solution import reprojection

    obs, fit, views = result.obs, result.fit, result.views
    names = views.names
    rows = max(result.calibration[n].grid_position[0] for n in names) + 1
    cols = max(result.calibration[n].grid_position[1] for n in names) + 1
    w, h = views.image_size
    used = fit.active[obs.cam, obs.frame] & fit.corner_ok
    out = []
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.0 * rows + 0.6), squeeze=False)
    for c, n in enumerate(names):
        r, k = result.calibration[n].grid_position
        ax = axes[r][k]
        m = obs.cam == c
        ax.scatter(obs.uv[m & used, 0], obs.uv[m & used, 1], s=1, c="tab:blue")
        ax.scatter(obs.uv[m & ~used, 0], obs.uv[m & ~used, 1], s=3, c="tab:red")
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_title(f"{n}: {result.report.cameras[n].coverage:.0%} of cells", fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle("detected corners (blue used, red rejected)", fontsize=9)
    fig.tight_layout()
    path = stem.with_name(stem.name + "_coverage.png")
    publish_figure(path, fig, 90)  # whole or absent, never a cut PNG
    plt.close(fig)
    out.append(path)

    res = reprojection(fit.solution, result.points, obs)
    residuals = result.report.rectification_residuals
    panels = 2 if residuals else 1
    fig, axes = plt.subplots(1, panels, figsize=(5 * panels, 4), squeeze=False)
    ax = axes[0][0]
    ax.scatter(res[used, 0], res[used, 1], s=1, alpha=0.4)
    lim = max(0.2, float(np.percentile(np.abs(res[used]), 99.5)) * 1.2) if used.any() else 1.0
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_title(f"reprojection residuals (px), RMS {fit.solution.rms:.3f}", fontsize=9)
    if residuals:
        ax = axes[0][1]
        pairs = residuals.pairs
        labels = list(pairs)
        raw = [pairs[p].raw.rms for p in labels]
        net = [pairs[p].net.rms for p in labels]
        x = np.arange(len(labels))
        ax.bar(x - 0.2, raw, 0.4, label="raw")
        ax.bar(x + 0.2, net, 0.4, label="net of camera placement")
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=90, fontsize=6)
        ax.set_ylabel("RMS cross-disparity (px)")
        ax.set_title("held-out rectification residuals per neighbour pair", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path = stem.with_name(stem.name + "_residuals.png")
    publish_figure(path, fig, 90)  # whole or absent, never a cut PNG
    plt.close(fig)
    out.append(path)
    return out
