"""Hostile takes and output folders for take, miv, usd and process (h-rel): one line, a documented exit code."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from hostile_support import one_line  # type: ignore[import-not-found]
from reliab_support import record_tiny, rigctl  # type: ignore[import-not-found]


@pytest.fixture(scope="module")
def tiny(module_tmp: Callable[[str], Path]) -> Path:
    """A recorded take of the simulated 3x3 rig, 2 frame sets of 96x54."""
    return record_tiny(module_tmp("rel"), "t", 2, "motion=false")


def copy(take: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(take, tmp_path / "t"))


@pytest.mark.parametrize("verb", ["info", "check", "export"])
def test_camera_file_in_a_symlink_loop_is_one_line(tiny: Path, tmp_path: Path, verb: str) -> None:
    take = copy(tiny, tmp_path)
    essence = take / "cameras" / "r0c0.essence"
    essence.unlink()
    essence.symlink_to("r0c0.essence")  # a link to itself: resolving it loops
    extra = ["--out", str(tmp_path / "out")] if verb == "export" else []
    res = rigctl("take", verb, str(take), *extra)
    if verb == "check":  # check lists its problems, then counts them
        assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
        assert "r0c0.essence" in res.stderr and "loop of symbolic links" in res.stderr, res.stderr
    else:
        one_line(res, 3, "r0c0.essence", "loop of symbolic links")
