"""The MIV camera file reader (rigctl.interop.miv_import.read_content) fed anything: a content or the
project's one-line error, never another exception. Inputs: any text, and a valid three-camera file with one
value replaced by anything a careless or hostile writer might put there."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rigctl.errors import RigctlError
from rigctl.interop.miv_import import read_content

PROPERTY = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.lists(st.one_of(st.integers(-5, 5), st.floats(allow_nan=True)), max_size=4),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=3),
)
KEYS = ["Name", "Position", "Rotation", "Depth_range", "Resolution", "Projection", "Focal", "Principle_point",
        "BitDepthColor", "BitDepthDepth", "DepthColorSpace"]  # fmt: skip


def valid() -> dict[str, Any]:
    cams = []
    for i in range(3):
        cams.append({
            "Name": f"v{i}", "Position": [0.0, -0.1 * i, 0.0], "Rotation": [0.0, 0.0, 0.0],
            "Depth_range": [1.0, 5.0], "Resolution": [64, 48], "Projection": "Perspective", "Focal": [50.0, 50.0],
            "Principle_point": [32.0, 24.0], "BitDepthColor": 10, "BitDepthDepth": 16, "DepthColorSpace": "YUV420",
        })  # fmt: skip
    return {"Version": "4.0", "cameras": cams}


def read(path: Path) -> None:
    try:
        content = read_content(path)
    except RigctlError as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    assert content.spacing_x > 0 and len(content.cameras) >= 1


def test_the_valid_file_reads_as_a_row_of_three(tmp_path: Path) -> None:
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(valid()))
    content = read_content(path)
    assert sorted(c.grid_name for c in content.cameras) == ["r0c0", "r0c1", "r0c2"]
    assert abs(content.spacing_x - 0.1) < 1e-12


@PROPERTY
@given(camera=st.integers(0, 2), key=st.sampled_from(KEYS), value=VALUES)
def test_one_value_changed(tmp_path: Path, camera: int, key: str, value: Any) -> None:
    doc = valid()
    doc["cameras"][camera][key] = value
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(doc))
    read(path)


@PROPERTY
@given(text=st.text(max_size=200))
def test_any_text(tmp_path: Path, text: str) -> None:
    path = tmp_path / "cameras.json"
    path.write_text(text)
    read(path)


def test_a_number_of_thousands_of_digits_is_our_line_not_pythons(tmp_path: Path) -> None:
    """Python refuses to convert more than 4300 digits with a message naming sys.set_int_max_str_digits; the
    reader says what it refuses and names the file instead."""
    import pytest

    from rigctl.errors import RigFileError

    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(valid()).replace('"BitDepthColor": 10', '"BitDepthColor": ' + "1" * 5000, 1))
    with pytest.raises(RigFileError) as info:
        read_content(path)
    assert str(info.value) == f"{path}: not a camera file: a whole number of 5,000 digits (at most 100 are read)"
