"""Our EXR header attributes have one prefix, ``rigctl:`` (the README's table lists them); files written with
the prefixes of before (``rigctl.`` in depth EXRs, ``rigctl_`` in rendered views) read the same."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rigctl.disparity_layers import CONVENTION, NUKE, STEPS, read_disparity
from rigctl.exr import PREFIX, read_exr, write_exr


def _text(value: object) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def test_old_prefixes_are_read_under_the_new_one(tmp_path: Path) -> None:
    d = np.linspace(80, 120, 12 * 16, dtype=np.float32).reshape(12, 16)
    old = tmp_path / "old.exr"
    attrs = {"rigctl.camera": "r1c1", "rigctl.focal_px": "1838.000000", "rigctl_position": "1.5,1",
             "rigctl.disparityConvention": NUKE, "rigctl.disparitySteps": "2 1 -"}  # fmt: skip
    write_exr(old, {"disparityL.x": -2 * d, "disparityL.y": np.zeros_like(d)}, attrs)
    _, head = read_exr(old)
    assert _text(head["rigctl:camera"]) == "r1c1" and _text(head["rigctl:focal_px"]) == "1838.000000"
    assert _text(head["rigctl:position"]) == "1.5,1" and _text(head[CONVENTION]) == NUKE
    assert _text(head["rigctl.camera"]) == "r1c1"  # the file's own name is kept too
    # a depth EXR of the NUKE convention written under the old prefix is read as one under the new
    assert CONVENTION.startswith(PREFIX) and STEPS.startswith(PREFIX)
    assert np.array_equal(read_disparity(old), d)


def test_the_new_name_wins_over_an_old_one_in_the_same_file(tmp_path: Path) -> None:
    path = tmp_path / "both.exr"
    write_exr(path, {"Y": np.zeros((4, 4), np.float32)}, {"rigctl.camera": "r0c0", "rigctl:camera": "r2c2"})
    _, head = read_exr(path)
    assert _text(head["rigctl:camera"]) == "r2c2"
