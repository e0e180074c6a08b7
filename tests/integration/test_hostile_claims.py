"""Files from others that claim what cannot be (h-check): a rotation that is none, sequence numbers and frame-set
rows that disagree with the take, camera names written two ways, boards no detector can use, two grids in one
folder. Each is one line naming the file and the field, and a documented exit code; never exit 0."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import SHARED
from hostile_support import SIM_RIG, one_line, write_yaml  # type: ignore[import-not-found]
from reliab_support import rigctl  # type: ignore[import-not-found]

from rigctl.errors import EXIT_BAD_INPUT, EXIT_USAGE

STEREO = SHARED / "data" / "opencv-stereo-chessboard"


# ---- rig files: a grid position is written one way -----------------------------------------------------------
@pytest.mark.parametrize(("name", "right"), [("r01c0", "r1c0"), ("r1c00", "r1c0"), ("r٢c1", "r2c1")])
def test_a_rig_camera_written_with_a_leading_zero_is_refused_naming_the_right_name(
    tmp_path: Path, name: str, right: str
) -> None:
    """A rig file took r01c0 (a camera named unlike its grid folder's r1c0.png and its take's files), where a
    grid folder already refused r01c0.png."""
    rig: dict[str, Any] = yaml.safe_load(yaml.safe_dump(SIM_RIG))
    for cam in rig["cameras"]:
        if cam["name"] == right:
            cam["name"] = name
    path = write_yaml(tmp_path / "rig.yaml", rig)
    one_line(rigctl("plan", str(path)), EXIT_BAD_INPUT, f"{path}:", f"name {name} is written with", f"name it {right}")


# ---- chessboard board files: inner corners bounded --------------------------------------------------------------
@pytest.mark.parametrize(
    ("columns", "rows", "field"),
    [(2, 6, "columns"), (9, 1, "rows"), (10**9, 6, "columns"), (9, 10**12, "rows"), (9.5, 6, "columns"),
     (True, 6, "columns"), ("9", 6, "columns")],
)  # fmt: skip
def test_a_chessboard_file_with_corners_out_of_bounds_is_one_line(
    tmp_path: Path, columns: object, rows: object, field: str
) -> None:
    """A board file's columns and rows had no bound: 2 ended in OpenCV's assertion text, 10**9 asked for exabytes
    of corner coordinates; 9.5 and true were read as 9 and 1."""
    board = write_yaml(tmp_path / "board.yaml", {"type": "chessboard", "columns": columns, "rows": rows})
    res = rigctl("calibrate", str(STEREO), "--board", str(board), "--out", str(tmp_path / "c.yaml"), timeout=300)
    one_line(res, EXIT_BAD_INPUT, f"{board}: {field}: must be a whole number of inner corners 3 to 100")
    assert not (tmp_path / "c.yaml").exists()


@pytest.mark.parametrize("pattern", ["2x6", "9x101", "100000x100000"])
def test_a_chessboard_option_out_of_bounds_is_one_line(tmp_path: Path, pattern: str) -> None:
    res = rigctl("calibrate", str(STEREO), "--chessboard", pattern, "--out", str(tmp_path / "c.yaml"), timeout=300)
    one_line(res, EXIT_USAGE, f"--chessboard {pattern}: must be 3 to 100 inner corners a side")
