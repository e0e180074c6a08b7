"""Rig files: the shipped rigs load, and every kind of mistake is named by file, line and field."""

from __future__ import annotations

from pathlib import Path

import pytest

from rigctl.errors import RigFileError, SpecVersionError
from rigctl.rig import load_rig

REPO = Path(__file__).resolve().parents[2]
# the shipped simulated rig without its optional rig-control sections
SIM = (REPO / "rigs" / "sim-3x3.yaml").read_text().split("# Camera control through")[0]


def write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "x.yaml"
    p.write_text(text)
    return p


def test_shipped_rigs_load_by_path_and_by_name() -> None:
    paper = load_rig(REPO / "rigs" / "bmd-micro-studio-4k-3x3.yaml")
    assert paper.c0_px == pytest.approx(7352.94, abs=0.01)
    assert [c.name for c in paper.cameras] == [f"r{r}c{c}" for r in range(3) for c in range(3)]
    assert paper.cameras[0].device == "v4l2:///dev/video0"
    assert paper.camera("r1c1").x_m == 0 and paper.camera("r0c2").x_m == pytest.approx(0.12)
    assert paper.camera("r2c1").y_m == pytest.approx(0.078)
    sim = load_rig("sim-3x3")
    assert sim.c0_px == pytest.approx(paper.c0_px / 4)
    assert sim.fov_deg() == pytest.approx(paper.fov_deg())
    assert load_rig().name == "sim-3x3"  # the default
    assert load_rig("rigs/sim-3x3.yaml").name == "sim-3x3"  # contract path works from any directory
    # optional sections are absent, not empty; the simulated rig's control goes through the simulated bridge
    assert sim.model.storage is None and paper.model.storage is None
    assert sim.model.camera_control is not None and sim.model.camera_control.bridge == "sim://bridge"
    assert paper.model.tally is not None and paper.model.tally.protocol == "tsl-umd-3.1"


def test_round_trip_through_snapshot() -> None:
    from rigctl.rig import rig_from_dict

    rig = load_rig("bmd-micro-studio-4k-3x3")
    again = rig_from_dict(rig.to_dict())
    assert again.model == rig.model


@pytest.mark.parametrize(
    ("old", "new", "expect"),
    [
        (
            "  spacing_x_m: 0.120",
            "  spacing_x_m: -0.12",
            r"x\.yaml:20: grid\.spacing_x_m must be > 0, got -0\.12",
        ),
        ("  width_px: 960", "  width_px: 0", r"x\.yaml:11: format\.width_px must be > 0, got 0"),
        (
            "  focal_length_mm: 25.0",
            "  focal_length_mm: .nan",
            r"x\.yaml:16: lens\.focal_length_mm must be a finite",
        ),
        ("  rows: 3", "  rows: 3\n  colour: red", r"x\.yaml:19: grid\.colour is not a known field"),
        ("  pixel_format: UYVY", "  pixel_format: H264", r"x\.yaml:14: format\.pixel_format .*'H264'"),
        ("  - name: r2c2", "  - name: r3c2", r"cameras\[8\]\.name|r3c2 lies outside the 3x3 grid"),
        ("  - name: r2c2", "  - name: r1c1", r"r1c1 appears twice"),
        ("  - name: r2c2", "  - name: centre", r"x\.yaml:\d+: cameras\[8\]\.name must be a grid position"),
        ("    device: sim://r2c2", "    device: sim://r2c1", r"sim://r2c1 is used by two cameras"),
        ("lens:\n  focal_length_mm: 25.0\n", "", r"x\.yaml:\d+: lens is required"),
        ("  fps: 25", "  fps: [25", r"x\.yaml:\d+: not valid YAML"),
        # YAML 1.1 reads 12e-2 as text: the message says why and how to write it (it said only "must be a number")
        (
            "  spacing_x_m: 0.120",
            "  spacing_x_m: 12e-2",
            r"x\.yaml:20: grid\.spacing_x_m .*'12e-2' \(read as text:.*write 12\.0e-2\)",
        ),
        # Python's own words (sys.set_int_max_str_digits) and tracebacks once came out of these
        ("  width_px: 960", "  width_px: " + "9" * 5000, r"x\.yaml:11: format\.width_px: a whole number of 5,000"),
        ("spec: 1", "spec: 1\ncreated: 2001-13-45", r"x\.yaml:\d+: created: cannot read '2001-13-45': month must be"),
    ],
)
def test_mistakes_are_named(tmp_path: Path, old: str, new: str, expect: str) -> None:
    assert old in SIM
    path = write(tmp_path, SIM.replace(old, new, 1))
    with pytest.raises(RigFileError, match=expect):
        load_rig(path)


def test_line_numbers_point_at_the_field(tmp_path: Path) -> None:
    text = SIM.replace("  spacing_x_m: 0.120", "  spacing_x_m: -0.12")
    line = next(i for i, s in enumerate(text.splitlines(), 1) if "spacing_x_m" in s)
    with pytest.raises(RigFileError) as info:
        load_rig(write(tmp_path, text))
    assert str(info.value).startswith(f"{tmp_path / 'x.yaml'}:{line}: grid.spacing_x_m")


def test_newer_spec_is_refused_with_what_to_do(tmp_path: Path) -> None:
    with pytest.raises(SpecVersionError, match=r"x\.yaml:\d+: rig file spec 2 is newer .* upgrade rigctl"):
        load_rig(write(tmp_path, SIM.replace("spec: 1", "spec: 2")))


def test_missing_spec_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(RigFileError, match="spec is required"):
        load_rig(write(tmp_path, SIM.replace("spec: 1\n", "")))
    with pytest.raises(RigFileError, match="no such rig file"):
        load_rig(tmp_path / "nope.yaml")


def test_duplicate_keys_are_refused(tmp_path: Path) -> None:
    with pytest.raises(RigFileError, match=r"x\.yaml:\d+: duplicate key 'rows'"):
        load_rig(write(tmp_path, SIM.replace("  rows: 3", "  rows: 3\n  rows: 4")))


def test_optional_sections_validate_camera_names(tmp_path: Path) -> None:
    text = SIM + "tally:\n  protocol: tsl-umd-3.1\n  port: loop://\n  addresses:\n    r9c9: 4\n"
    with pytest.raises(RigFileError, match=r"tally\.addresses names r9c9"):
        load_rig(write(tmp_path, text))
    ok = SIM + "tally:\n  protocol: tsl-umd-3.1\n  port: loop://\n"
    assert load_rig(write(tmp_path, ok)).model.tally is not None


def tally_rig(tmp_path: Path, protocol: str, address: int) -> Path:
    return write(
        tmp_path, SIM + f"tally:\n  protocol: {protocol}\n  port: loop://\n  addresses:\n    r1c1: {address}\n"
    )


@pytest.mark.parametrize(
    ("protocol", "address"),
    [("tsl-umd-3.1", 0), ("tsl-umd-3.1", 126), ("tsl-umd-5.0", 127), ("tsl-umd-5.0", 1000), ("tsl-umd-5.0", 65534)],
)
def test_tally_addresses_up_to_what_the_protocol_carries_load(tmp_path: Path, protocol: str, address: int) -> None:
    tally = load_rig(tally_rig(tmp_path, protocol, address)).model.tally
    assert tally is not None and tally.addresses == {"r1c1": address}


@pytest.mark.parametrize(
    ("protocol", "address", "message"),
    [
        ("tsl-umd-3.1", 127, "tally.addresses.r1c1 must be 0..126 for tsl-umd-3.1, got 127"),
        ("tsl-umd-3.1", 1000, "tally.addresses.r1c1 must be 0..126 for tsl-umd-3.1, got 1000"),
        (
            "tsl-umd-5.0",
            65535,
            "tally.addresses.r1c1 is 65535, TSL UMD 5.0's broadcast index (every display of "
            "the screen): give r1c1 its own display, 0..65534",
        ),
        ("tsl-umd-5.0", 65536, "tally.addresses.r1c1 must be 0..65534 for tsl-umd-5.0, got 65536"),
        ("tsl-umd-5.0", -1, "tally.addresses.r1c1 must be >= 0, got -1"),
    ],
)
def test_tally_addresses_past_the_protocol_are_named(tmp_path: Path, protocol: str, address: int, message: str) -> None:
    path = tally_rig(tmp_path, protocol, address)
    line = path.read_text().splitlines().index(f"    r1c1: {address}") + 1
    with pytest.raises(RigFileError) as err:
        load_rig(path)
    assert str(err.value) == f"{path}:{line}: {message}"


@pytest.mark.parametrize(
    ("section", "field"), [("tally:\n  protocol: tsl-umd-5.0\n  port: loop://", "addresses"),
                           ("camera_control:\n  bridge: loop://", "camera_ids")]
)  # fmt: skip
def test_two_cameras_on_one_tally_address_or_camera_id_are_refused(tmp_path: Path, section: str, field: str) -> None:
    """A display lit for two cameras (the one not on air looks live), or one camera sent the other's
    settings: the second camera with the number is named, at its line."""
    path = write(tmp_path, SIM + f"{section}\n  {field}:\n    r0c0: 17\n    r1c1: 18\n    r2c2: 17\n")
    line = path.read_text().splitlines().index("    r2c2: 17") + 1
    with pytest.raises(RigFileError) as err:
        load_rig(path)
    head = section.split(":")[0]
    assert str(err.value) == f"{path}:{line}: {head}.{field}.r2c2 is 17, as is r0c0's: each camera needs its own"
    fine = write(tmp_path, SIM + f"{section}\n  {field}:\n    r0c0: 17\n    r1c1: 18\n    r2c2: 19\n")
    assert load_rig(fine).model is not None
    # the cameras not given one are numbered 1..N in the file's order: the first camera is 1
    first = load_rig(fine).camera_names[0]
    clash = write(tmp_path, SIM + f"{section}\n  {field}:\n    r2c2: 1\n")
    line = clash.read_text().splitlines().index("    r2c2: 1") + 1
    with pytest.raises(RigFileError) as err:
        load_rig(clash)
    assert str(err.value) == (
        f"{clash}:{line}: {head}.{field}.r2c2 is 1, as is {first}'s by default (1..N in the order of the cameras): "
        "each camera needs its own"
    )


@pytest.mark.parametrize("text", ["12e-2", "1.2e5", "-3E2", ".5e1", "1e+2", "7e0"])
def test_the_spelling_the_yaml_hint_suggests_is_read_as_that_number(text: str) -> None:
    import re

    import yaml

    from rigctl.yamlfile import _yaml11_float_hint

    assert isinstance(yaml.safe_load(text), str)  # what the hint is about
    fixed = re.search(r"so write (\S+)\)$", _yaml11_float_hint(text))
    assert fixed is not None and yaml.safe_load(fixed[1]) == pytest.approx(float(text))
