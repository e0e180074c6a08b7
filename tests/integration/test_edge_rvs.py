"""Depth that ends where the subject ends, judged by a standard renderer: MPEG's RVS (built from its source)
renders r1c1 of the ideal seed-3 take from the other eight cameras' colour, once with our depth and once
with the true depth, both through our MIV export; on the pixels RVS calls valid (not a filled hole), the two
must be within 2 dB of Y PSNR against r1c1's own picture. A halo of depth past the silhouette puts screen
colour on the subject there (28.4 against 40.3 dB before depth ended at the subject). The same run scores
the depth's two sides of the silhouette over the nine cameras."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from interop_support import reference_tool
from tests_support import run_rigctl

from rigctl import registry
from rigctl.depth.grid import TakeGrid
from rigctl.depth.metrics import silhouette
from rigctl.disparity_layers import read_disparity
from rigctl.interop import yuv
from rigctl.interop.miv import depth_name, texture_name
from rigctl.pfm import read_pfm

W, H = 960, 540
TARGET = "r1c1"


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    out = module_tmp("edge")
    res = run_rigctl(
        "record", "--take", "ideal", "--frames", "1", "--out", str(out),
        "--sim", "ideal=true", "--sim", "seed=3", "--sim", "motion=false", "--sim", "deterministic=true",
        "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return out / "ideal"


@pytest.fixture(scope="module")
def our_depth(take: Path) -> Path:
    out = take.parent / "depth"
    # nine cameras with the default preset: about two minutes on two idle cores, several on busy ones
    res = run_rigctl("depth", str(take), "--out", str(out), "--json", timeout=1800)
    assert res.returncode == 0, res.stderr
    return out


def export(take: Path, disparity: Path, name: str) -> Path:
    out = take.parent / name
    res = run_rigctl("miv", "export", str(take), str(disparity), "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out


def rvs_luma(content: Path, work: Path) -> tuple[np.ndarray, np.ndarray]:
    """RVS's 10-bit luma of TARGET from the other cameras, and its mask of filled holes."""
    doc = json.loads((content / "cameras.json").read_text())
    cams = {c["Name"]: c for c in doc["cameras"]}
    sources = [n for n in cams if n != TARGET]
    work.mkdir(parents=True, exist_ok=True)
    (work / "virtual.json").write_text(json.dumps({"Version": "4.0", "cameras": [dict(cams[TARGET], Name="v")]}))
    (work / "inputs.json").write_text(json.dumps(doc))
    config = {
        "Version": "3.0", "InputCameraParameterFile": "inputs.json", "VirtualCameraParameterFile": "virtual.json",
        "InputCameraNames": sources, "VirtualCameraNames": ["v"],
        "ViewImageNames": [str(content / texture_name(n, W, H)) for n in sources],
        "DepthMapNames": [str(content / depth_name(n, W, H)) for n in sources],
        "OutputFiles": ["v.yuv"], "OutputMasks": ["mask.yuv"], "StartFrame": 0, "NumberOfFrames": 1,
        "Precision": 1.0, "ColorSpace": "YUV", "ViewSynthesisMethod": "Triangles", "BlendingMethod": "Simple",
        "BlendingFactor": 5.0,
    }  # fmt: skip
    (work / "rvs.json").write_text(json.dumps(config))
    proc = subprocess.run(
        [str(reference_tool("rvs")), "rvs.json"], cwd=work, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    y = yuv.read_frame(work / "v.yuv", W, H, 10)[0]
    mask = yuv.read_frame(work / "mask.yuv", W, H, 8)[0]
    return y.astype(np.float64), mask > 127


def y_psnr(y: np.ndarray, reference: np.ndarray, valid: np.ndarray) -> float:
    return float(10 * np.log10(1023**2 / np.mean((y[valid] - reference[valid]) ** 2)))


# Issue 31 asks for 2 dB. The gap was 2.17 dB (38.16 against 40.33) with best's cost volume: half of its squared
# error came from 525 pixels beside the outline that RVS painted with the subject where r1c1 shows the screen,
# warped there by source pixels next to a nearer surface that had taken its disparity (foreground fattening).
# No camera's depth may now sit in front of what most other views see there (edge.occlusion_order).
RVS_GAP_DB = 2.0


def test_rvs_with_our_depth_comes_close_to_rvs_with_the_true_depth(take: Path, our_depth: Path) -> None:
    grid = TakeGrid(take).grid(0)
    reference = yuv.rgb_to_ycbcr(grid.images[TARGET], 10)[0].astype(np.float64)
    box = registry.simulated_burnin_box(take, W)
    scores = {}
    for name, disparity in (("true", take / "truth" / "disparity"), ("ours", our_depth)):
        y, hole = rvs_luma(export(take, disparity, f"content-{name}"), take.parent / f"rvs-{name}")
        valid = ~hole
        if box is not None:
            valid[box[0] : box[1], box[2] : box[3]] = False  # the burnt-in id: no view of the scene shows it
        scores[name] = y_psnr(y, reference, valid)
    print(f"RVS {TARGET} from the other eight, Y PSNR on its valid pixels: true depth {scores['true']:.2f} dB, "
          f"ours {scores['ours']:.2f} dB")  # fmt: skip
    assert scores["true"] > 35.0
    assert scores["ours"] >= scores["true"] - RVS_GAP_DB, scores


def test_depth_ends_where_the_subject_ends_on_all_nine_cameras(take: Path, our_depth: Path) -> None:
    """Over the nine cameras: depth where the truth has none on at most 0.05 % as many pixels as the subject
    has (it was 0.72 %: a 1-px halo and the burnt-in id), none on at most 0.5 % of the subject."""
    false = missed = subject = 0
    for p in sorted((take / "truth" / "disparity" / "000000").glob("*.pfm")):
        truth, est = read_pfm(p), read_disparity(our_depth / "000000" / f"{p.stem}.exr")  # no PFM unless asked
        sc = silhouette(est, truth, np.isfinite(truth))
        n = int(np.isfinite(truth).sum())
        false += int(sc["false_fg_pixels"])
        missed += round(sc["missed_fg_pct"] * n / 100)
        subject += n
    print(f"false foreground {100 * false / subject:.3f} %, missed {100 * missed / subject:.3f} % of {subject} px")
    assert false <= 0.0005 * subject
    assert missed <= 0.005 * subject
