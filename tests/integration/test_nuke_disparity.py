"""Disparity layers as NUKE names them (issue 29, point 2): on the middle row of an ideal simulated take every
camera's depth EXR carries ``disparityL`` (this view onto the camera to its right) and ``disparityR`` (onto
the camera to its left), end cameras included, and ``disparityV`` onto the camera below; sampling the
neighbour where a field points matches this view's colour far better than with the field negated. A depth
folder of EXRs only is read back by ``rigctl render`` as its PFMs are; an EXR written before the convention is
read by the old rule, one in an unknown convention is refused in one line."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from tests_support import run_rigctl

from rigctl.disparity_layers import CONVENTION, NUKE, STEPS, Steps, read_disparity, steps
from rigctl.errors import TakeError
from rigctl.exr import read_exr, write_exr
from rigctl.pfm import read_pfm

ROW = ("r1c0", "r1c1", "r1c2")
CAMS = (*ROW, "r2c1")


@pytest.fixture(scope="module")
def depth(module_tmp: Callable[[str], Path]) -> tuple[Path, Path]:
    root = module_tmp("nuke")
    res = run_rigctl(
        "record", "--take", "ideal", "--frames", "1", "--out", str(root), "--sim", "ideal=true",
        "--sim", "deterministic=true", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    take, out = root / "ideal", root / "depth"
    res = run_rigctl(
        "depth", str(take), "--out", str(out), "--near", "1.95", "--far", "3.0", "--cameras", *CAMS,
        "--formats", "exr,pfm",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return take, out


def _view(folder: Path, cam: str) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    return read_exr(folder / "000000" / f"{cam}.exr")


def _warp_error(this: dict[str, np.ndarray], other: dict[str, np.ndarray], fx: np.ndarray, fy: np.ndarray) -> float:
    """Mean colour difference between this view and the other sampled where (fx, fy) points, over this
    view's subject pixels with an estimate whose target lies inside the other picture."""
    h, w = fx.shape
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    mx, my = xs + fx, ys + fy
    sampled = cv2.remap(other["RGB"].astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    use = (this["A"] > 0.99) & (this["confidence.Y"] > 0) & (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    assert use.sum() > 1000, use.sum()
    return float(np.abs(sampled[use] - this["RGB"][use]).mean())


def test_every_row_camera_carries_both_fields_and_each_points_at_its_match(depth: tuple[Path, Path]) -> None:
    _, out = depth
    views = {c: _view(out, c) for c in CAMS}
    for cam in ROW:
        ch, head = views[cam]
        assert {"disparityL.x", "disparityL.y", "disparityR.x", "disparityR.y", "disparityV.y"} <= set(ch), cam
        assert head[CONVENTION] == NUKE
    pairs = [
        ("r1c0", "r1c1", "disparityL"),
        ("r1c1", "r1c2", "disparityL"),
        ("r1c1", "r1c0", "disparityR"),
        ("r1c2", "r1c1", "disparityR"),
        ("r1c1", "r2c1", "disparityV"),
    ]
    for cam, other, layer in pairs:
        this = views[cam][0]
        fx = this.get(f"{layer}.x", np.zeros_like(this[f"{layer}.y"]))
        fy = this[f"{layer}.y"]
        right = _warp_error(this, views[other][0], fx, fy)
        negated = _warp_error(this, views[other][0], -fx, -fy)
        assert right * 2 <= negated, (cam, layer, other, right, negated)
        assert right < 0.02, (cam, layer, other, right)  # scene-linear colour; a wrong field is ~10x this


def test_render_reads_a_depth_folder_of_exrs_as_its_pfms(depth: tuple[Path, Path]) -> None:
    take, out = depth
    exr_only = out.parent / "exr-only"
    shutil.copytree(out, exr_only)
    for p in exr_only.glob("000000/*.pfm"):
        p.unlink()
    for cam in ROW:
        pfm = out / "000000" / f"{cam}.pfm"
        assert np.array_equal(read_disparity(exr_only / "000000" / f"{cam}.exr"), read_pfm(pfm), equal_nan=True)
    scores = []
    for folder in (out, exr_only):
        res = run_rigctl(
            "render", str(take), "--disparity", str(folder), "--leave-one-out", "--cameras", "r1c1", "--json"
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        scores.append(json.loads(res.stdout)["leave_one_out"][0]["psnr_db"])
    assert scores[0] == scores[1]


def test_an_exr_from_before_the_convention_is_read_by_the_old_rule(tmp_path: Path) -> None:
    d = np.linspace(80, 120, 12 * 16, dtype=np.float32).reshape(12, 16)
    old = tmp_path / "old.exr"
    write_exr(old, {"disparityL.x": d, "disparityL.y": np.zeros_like(d), "depth.Z": 1 / d}, {})
    assert np.array_equal(read_disparity(old), d)
    only_r = tmp_path / "old-right.exr"
    write_exr(only_r, {"disparityR.x": -d, "disparityR.y": np.zeros_like(d)}, {})
    assert np.array_equal(read_disparity(only_r), d)
    new = tmp_path / "new.exr"
    write_exr(new, {"disparityL.x": -2 * d, "disparityL.y": np.zeros_like(d)}, {CONVENTION: NUKE, STEPS: "2 1 -"})
    assert np.array_equal(read_disparity(new), d)


@pytest.mark.parametrize(
    "channels, attrs, says",
    [
        ({"disparityL.x": np.zeros((4, 4), np.float32)}, {CONVENTION: "ocula-2"}, "not a disparity convention"),
        ({"disparityL.x": np.zeros((4, 4), np.float32)}, {CONVENTION: NUKE}, f"no {STEPS}"),
        ({"disparityL.x": np.zeros((4, 4), np.float32)}, {CONVENTION: NUKE, STEPS: "0 1 1"}, "positive"),
        ({"depth.Z": np.zeros((4, 4), np.float32)}, {}, "no disparityL/disparityR"),
        ({"disparityL.x": np.full((4, 4), np.nan, np.float32)}, {}, "NaN"),
    ],
)
def test_a_depth_exr_it_cannot_read_is_refused_in_one_line(
    tmp_path: Path, channels: dict[str, np.ndarray], attrs: dict[str, str], says: str
) -> None:
    p = tmp_path / "x.exr"
    write_exr(p, channels, attrs)
    with pytest.raises(TakeError, match=says) as err:
        read_disparity(p)
    assert str(p) in str(err.value) and "\n" not in str(err.value)


def test_steps_on_grids_of_one_row_one_column_and_three_by_three() -> None:
    ratio = 78 / 120
    grid = {f"r{r}c{c}": (float(c), r * ratio) for r in range(3) for c in range(3)}
    assert steps(grid, "r0c0") == Steps(1.0, 1.0, pytest.approx(ratio))
    assert steps(grid, "r2c2") == Steps(1.0, 1.0, pytest.approx(ratio))  # end of row and column: the grid's
    row = {f"r0c{c}": (float(c), 0.0) for c in (0, 2, 3)}
    assert steps(row, "r0c0") == Steps(2.0, 1.0, None)
    col = {f"r{r}c0": (0.0, r * ratio) for r in range(2)}
    assert steps(col, "r0c0") == Steps(None, None, pytest.approx(ratio))
