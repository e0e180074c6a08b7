"""The demo report's section on novel views: leave-one-out for every camera with our depth and with the
true disparity, and a strip of views along a path across the array."""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np

from rigctl.publish import publish_png
from rigctl.render.inputs import RenderInput
from rigctl.render.views import leave_one_out, path_positions, renderer_for

log = logging.getLogger(__name__)


def novel_views_section(
    take: Path, depth: Path, out: Path, ignore: tuple[int, int, int, int] | None = None, steps: int = 7
) -> list[str]:
    """Markdown lines; writes ``novel-views.png`` (a strip from 0,1 to 2,1 over grey) into ``out``."""
    truth = take / "truth" / "disparity"
    tables = {"our depth": leave_one_out(RenderInput(take, depth), [0], None, ignore)}
    if truth.is_dir():
        tables["true disparity"] = leave_one_out(RenderInput(take, truth), [0], None, ignore)
    lines = ["## Novel views", "", "Leave-one-out: each camera rendered from its four nearest others, scored "
             "on its keyed subject (`rigctl render --leave-one-out`).", "",
             "| camera | " + " | ".join(f"PSNR dB, {k} | SSIM, {k}" for k in tables) + " |",
             "|---|" + "---|---|" * len(tables)]  # fmt: skip
    by_cam = {k: {r["camera"]: r for r in rows} for k, rows in tables.items()}
    for cam in sorted(next(iter(by_cam.values()))):
        cells = [f"{by_cam[k][cam]['psnr_db']:.2f} | {by_cam[k][cam]['ssim']:.4f}" for k in tables]
        lines.append(f"| {cam} | " + " | ".join(cells) + " |")
    frame = RenderInput(take, depth).frame(0)
    ren = renderer_for(frame)
    tiles = []
    for col, row in path_positions([(0.0, 1.0), (2.0, 1.0)], steps):
        rgba = ren.render(*frame.position(col, row)).rgba
        comp = rgba[..., :3] * rgba[..., 3:] + 0.5 * (1 - rgba[..., 3:])
        tiles.append(cv2.resize(comp, (comp.shape[1] // 3, comp.shape[0] // 3), interpolation=cv2.INTER_AREA))
    strip = np.concatenate(tiles, axis=1)
    publish_png(out / "novel-views.png", np.clip(strip[..., ::-1] * 255 + 0.5, 0, 255).astype(np.uint8))
    lines += ["", f"Novel views with our depth along the middle row from 0,1 to 2,1 ({steps} positions):", "",
              "![novel views along a path](novel-views.png)", ""]  # fmt: skip
    return lines
