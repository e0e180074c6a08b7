"""Files from others that claim what cannot be (h-check): a rotation that is none, sequence numbers and frame-set
rows that disagree with the take, camera names written two ways, boards no detector can use, two grids in one
folder. Each is one line naming the file and the field, and a documented exit code; never exit 0."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml
from hostile_support import SIM_RIG, one_line, write_yaml  # type: ignore[import-not-found]
from reliab_support import rigctl  # type: ignore[import-not-found]

from rigctl.errors import EXIT_BAD_INPUT


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
