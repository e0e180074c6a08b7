"""A worker runs OpenCV on as many threads as the compiled kernels (issue 24: the semi-global matcher on one
thread was a third of the depth time), which is only right if OpenCV's results do not depend on its thread
count: a frame set's files (EXR, PFM, PNG of every camera, preset best) are byte-identical at 1, 2 and 3."""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from pathlib import Path

import cv2
import numba
import pytest

from rigctl.depth.export import FORMATS, Exporter
from rigctl.depth.options import DepthOptions
from rigctl.depth.pipeline import TakeProcessor
from rigctl.depth.sources import OneGrid
from rigctl.farm.frame import pin_threads
from rigctl.farm.membench import scaled
from rigctl.simulated_presenter import presenter


@pytest.fixture
def restore_threads() -> Iterator[None]:
    before = cv2.getNumThreads()
    yield
    cv2.setNumThreads(before)


def _files(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in root.rglob("*") if p.is_file()
    }


def test_outputs_do_not_depend_on_opencvs_threads(tmp_path: Path, restore_threads: None) -> None:
    ds = presenter(False)  # realistic: camera noise, the matcher's and the filters' every path
    grid, d_range = scaled(ds.grid, ds.d_range, 480, 272)
    outputs = {}
    for threads in (1, 2, 3):
        cv2.setNumThreads(threads)
        out = tmp_path / f"t{threads}"
        opt = DepthOptions(preset="best", disparity_range=d_range)
        TakeProcessor(OneGrid(grid), opt, exporter=Exporter(out, formats=FORMATS, atomic=True)).process(0)
        outputs[threads] = _files(out)
    assert len(outputs[1]) >= 9 * 3  # every camera's EXR, PFM and PNG
    assert any(name.endswith(".exr") for name in outputs[1])
    assert outputs[2] == outputs[1]
    assert outputs[3] == outputs[1]


def test_a_worker_gives_opencv_the_kernels_threads(restore_threads: None) -> None:
    cv2.setNumThreads(1)
    pin_threads()
    assert cv2.getNumThreads() == numba.get_num_threads()
