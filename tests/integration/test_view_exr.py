"""A rendered view's EXR as compositors expect it, read by a reader nobody here wrote (OpenImageIO's
``oiiotool --info -v``, from Debian): half-float colour, the take's time, and the camera as OpenEXR's
``worldToCamera`` / ``worldToNDC``, whose projection lands where the take's rectification puts a point."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from tests_support import oiio_info, rectified_ndc_error, run_rigctl

from rigctl.exr import read_exr
from rigctl.take.manifest import read_manifest


@pytest.fixture(scope="module")
def views(module_tmp: Callable[[str], Path]) -> tuple[Path, Path]:
    out = module_tmp("view-exr")
    res = run_rigctl("record", "--take", "t", "--frames", "1", "--out", str(out), "--sim", "ideal=true",
                     "--sim", "motion=false", "--force")  # fmt: skip
    assert res.returncode == 0, res.stderr
    take = out / "t"
    res = run_rigctl("render", str(take), "--disparity", str(take / "truth" / "disparity"), "--at", "1,1",
                     "--at", "2,0", "--out", str(out / "views"))  # fmt: skip
    assert res.returncode == 0, res.stderr
    return take, out / "views" / "000000"


def test_oiiotool_lists_half_colour_the_time_and_the_camera(views: tuple[Path, Path]) -> None:
    info = oiio_info(views[1] / "c1r1.exr")
    assert re.search(r"4 channel, half openexr", info), info
    assert "channel list: R, G, B, A" in info
    assert "framesPerSecond: 25/1" in info
    assert re.search(r"smpte:TimeCode: \d\d:\d\d:\d\d:\d\d", info), info
    assert "worldToCamera:" in info and "worldToNDC:" in info
    assert 'compression: "piz"' in info


@pytest.mark.parametrize(("stem", "camera"), [("c1r1", "r1c1"), ("c2r0", "r0c2")])
def test_world_to_ndc_projects_where_the_rectification_does(views: tuple[Path, Path], stem: str, camera: str) -> None:
    take, folder = views
    assert rectified_ndc_error(take, camera, folder / f"{stem}.exr", points=20) < 1e-3
    rect = read_manifest(take).rectification
    assert rect is not None
    centre = np.array(rect.positions_m[camera])
    _, header = read_exr(folder / f"{stem}.exr")
    cam = np.asarray(header["worldToCamera"], np.float64)
    here = np.append(centre + np.array([0.0, 0.0, 2.0]), 1.0) @ cam  # 2 m straight ahead
    assert np.allclose(here[:3], [0.0, 0.0, 2.0], atol=1e-5)  # RenderMan camera space: +z ahead
    above = np.append(centre + np.array([0.0, -0.1, 2.0]), 1.0) @ cam  # our y is down: 0.1 m up is +y there
    assert above[1] == pytest.approx(0.1, abs=1e-5)
