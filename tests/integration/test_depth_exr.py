"""A depth EXR as compositors expect it, read by a reader nobody here wrote (OpenImageIO's ``oiiotool --info -v``):
half-float colour, float32 depth, disparity and confidence, the take's time, and the rectified camera as
OpenEXR's ``worldToCamera`` / ``worldToNDC``, whose projection lands where the take's rectification (``rigctl
rectify`` on a tiny simulated take recorded with ``--sim deterministic=true``) puts a point."""

from __future__ import annotations

import re
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from reliab_support import make_tiny  # type: ignore[import-not-found]
from tests_support import oiio_info, rectified_ndc_error, run_rigctl

from rigctl.exr import read_exr
from rigctl.take.manifest import read_manifest

CAMS = ("r1c1", "r0c2")


@pytest.fixture(scope="module")
def depth(module_tmp: Callable[[str], Path]) -> tuple[Path, Path]:
    root = module_tmp("depth-exr")
    _, rect = make_tiny(root, frames=1)
    out = root / "depth"
    res = run_rigctl("depth", str(rect), "--out", str(out), "--preset", "fast", "--cameras", *CAMS)
    assert res.returncode == 0, res.stderr
    return rect, out / "000000"


def test_oiiotool_lists_half_colour_float_depth_the_time_and_the_camera(depth: tuple[Path, Path]) -> None:
    info = oiio_info(depth[1] / "r1c1.exr")
    # OpenImageIO names each channel's format when they differ: the picture half, the rest float
    listed = re.search(r"channel list: (.*)", info)
    assert listed is not None, info
    formats = dict(re.findall(r"([\w.]+) \((half|float)\)", listed[1]))
    for ch in ("R", "G", "B", "A"):
        assert formats.get(ch) == "half", (ch, info)
    for ch in ("depth.Z", "confidence.Y", "disparityL.x", "disparityR.x", "disparityV.y"):
        assert formats.get(ch) == "float", (ch, info)
    assert "framesPerSecond: 25/1" in info
    assert re.search(r"smpte:TimeCode: \d\d:\d\d:\d\d:\d\d", info), info
    assert "worldToCamera:" in info and "worldToNDC:" in info
    assert 'compression: "rle"' in info  # issue 24: half ZIP's encoding time, lossless, read by every OpenEXR


def test_another_reader_decodes_the_rle_file_to_our_values(depth: tuple[Path, Path]) -> None:
    """OpenImageIO's statistics of every channel (its own decoder of the run-length file) are those of the
    values we wrote, as OpenEXR reads them back: a codec that lost or shifted a run would change them."""
    path = depth[1] / "r1c1.exr"
    proc = subprocess.run(["oiiotool", "--stats", "-v", str(path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    listed = re.search(r"channel list: (.*)", proc.stdout)
    assert listed is not None, proc.stdout
    names = re.findall(r"([\w.]+) \((?:half|float)\)", listed[1])
    stats = {}
    for k in ("Min", "Max", "Avg"):
        line = re.search(rf"Stats {k}: ([^(\n]*)", proc.stdout)
        assert line is not None, proc.stdout
        stats[k] = [float(v) for v in line[1].split()]
    channels, _ = read_exr(path)
    planes = {n: channels["RGB"][..., "RGB".index(n)] if n in "RGB" else channels[n] for n in names}
    assert len(names) == 12 and float(np.ptp(planes["depth.Z"])) > 0  # a real depth, not a constant
    for i, n in enumerate(names):
        v = planes[n].astype(np.float64)
        assert stats["Min"][i] == pytest.approx(v.min(), abs=1e-5), n
        assert stats["Max"][i] == pytest.approx(v.max(), abs=1e-5), n
        assert stats["Avg"][i] == pytest.approx(v.mean(), abs=1e-5), n


@pytest.mark.parametrize("camera", CAMS)
def test_world_to_ndc_projects_where_the_rectification_does(depth: tuple[Path, Path], camera: str) -> None:
    take, folder = depth
    assert rectified_ndc_error(take, camera, folder / f"{camera}.exr", points=200) < 1e-3  # 2.8e-6 px measured
    rect = read_manifest(take).rectification
    assert rect is not None
    centre = np.array(rect.positions_m[camera])
    channels, header = read_exr(folder / f"{camera}.exr")
    assert channels["depth.Z"].shape == (rect.image_size[1], rect.image_size[0])
    cam = np.asarray(header["worldToCamera"], np.float64)
    ahead = np.append(centre + np.array([0.05, -0.1, 2.0]), 1.0) @ cam
    assert np.allclose(ahead[:3], [0.05, 0.1, 2.0], atol=1e-5)  # RenderMan camera space: y up, +z ahead
