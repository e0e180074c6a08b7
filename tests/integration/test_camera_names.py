"""A camera's name is its grid position ``r{row}c{col}``, written one way (ASCII digits, no leading zeros) in every
file rigctl reads: a take's manifest, a calibration, a grid folder. A name written another way (``r01c0``,
``r٢c1``) is refused in one line naming the file, its line, the field and the name to use, exit 3."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from hostile_support import one_line  # type: ignore[import-not-found]
from reliab_support import copy_take, edit_manifest, record_tiny, rewrite_records, rigctl  # type: ignore[import-not-found]

from rigctl.errors import EXIT_BAD_INPUT, EXIT_CHECK_FAILED, EXIT_USAGE
from rigctl.take.index import camera_tag

MISSPELT = [("r01c0", "r1c0"), ("r1c00", "r1c0"), ("r٢c1", "r2c1")]
IDS = ["leading zero in the row", "leading zero in the column", "arabic-indic digit"]


@pytest.fixture(scope="module")
def ideal(module_tmp: Callable[[str], Path]) -> Path:
    """An ideal tiny take: rectified as recorded (depth reads it), its manifest holding rectification.positions_m."""
    return record_tiny(module_tmp("names-ideal"), "ideal", 2, "ideal=true", "motion=false")


def key_line(path: Path, *loc: str | int) -> int:
    """The line (from 1) of the key or item at ``loc`` in the YAML file ``path``."""
    node: Any = yaml.compose(path.read_text(encoding="utf-8"))
    line = 1
    for key in loc:
        if isinstance(key, int):
            node = node.value[key]
            line = node.start_mark.line + 1
            continue
        for k, v in node.value:
            if k.value == key:
                line, node = k.start_mark.line + 1, v
                break
        else:
            raise KeyError(key)
    return line


def _renamed(d: dict[str, Any], old: str, new: str) -> dict[str, Any]:
    return {(new if k == old else k): v for k, v in d.items()}  # in order: sets.csv's header follows it


def rename_camera(take: Path, old: str, new: str, where: str) -> None:
    """Name camera ``old`` ``new`` in the take: in ``cameras`` (with its files, its index records' camera tag and
    sets.csv's header: a take another tool wrote that way, whole), in ``rectification.positions_m`` or in the
    manifest's rig snapshot."""
    if where == "cameras":
        for kind in ("essence", "index"):
            (take / "cameras" / f"{old}.{kind}").rename(take / "cameras" / f"{new}.{kind}")
        rewrite_records(take / "cameras" / f"{new}.index", lambda _i, f: f.update(res=camera_tag(new)))
        sets = take / "sets.csv"
        header, rest = sets.read_text(encoding="utf-8").split("\n", 1)
        sets.write_text(",".join(new if c == old else c for c in header.split(",")) + "\n" + rest, encoding="utf-8")

    def edit(m: dict[str, Any]) -> None:
        if where == "cameras":
            m["cameras"] = _renamed(m["cameras"], old, new)
            m["cameras"][new].update(essence=f"cameras/{new}.essence", index=f"cameras/{new}.index")
        elif where == "positions_m":
            m["rectification"]["positions_m"] = _renamed(m["rectification"]["positions_m"], old, new)
        else:
            next(c for c in m["rig"]["cameras"] if c["name"] == old)["name"] = new

    edit_manifest(take, edit)


def _loc(take: Path, name: str, where: str) -> tuple[str | int, ...]:
    if where == "cameras":
        return ("cameras", name)
    if where == "positions_m":
        return ("rectification", "positions_m", name)
    rig = yaml.safe_load((take / "take.yaml").read_text(encoding="utf-8"))["rig"]
    return ("rig", "cameras", next(i for i, c in enumerate(rig["cameras"]) if c["name"] == name), "name")


# ---- take manifests ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("verb", ["info", "check", "export", "depth"])
@pytest.mark.parametrize("where", ["cameras", "positions_m", "rig"])
@pytest.mark.parametrize(("name", "right"), MISSPELT, ids=IDS)
def test_a_take_camera_written_with_a_leading_zero_is_refused_naming_the_right_name(
    ideal: Path, tmp_path: Path, name: str, right: str, where: str, verb: str
) -> None:
    """take.yaml took r01c0 (and r٢c1) wherever it names a camera, where a rig file and a grid folder refused it:
    a take written that way by another tool, whole (files, index, sets.csv), was read, exported and estimated
    as a camera r01c0, exit 0. Every reader refuses it now on its line, naming the name to use."""
    take = copy_take(ideal, tmp_path / "t")
    rename_camera(take, right, name, where)
    manifest = take / "take.yaml"
    at = f"{manifest}:{key_line(manifest, *_loc(take, name, where))}:"
    said = f"camera name {name} is written with"
    if verb == "check":
        res = rigctl("take", "check", str(take))
        assert res.returncode == EXIT_CHECK_FAILED and "Traceback" not in res.stderr, res.stderr
        assert at in res.stderr and said in res.stderr and f"name it {right}" in res.stderr, res.stderr
        return
    out = tmp_path / "out"
    cmd = ["take", verb, str(take)] if verb != "depth" else ["depth", str(take), "--preset", "fast"]
    cmd += ["--out", str(out)] if verb != "info" else []
    one_line(rigctl(*cmd), EXIT_BAD_INPUT, at, said, f"name it {right}")
    assert not out.exists() or not any(p.is_file() for p in out.rglob("*"))


def test_a_take_named_as_recorded_is_read(ideal: Path) -> None:
    """The recorder's own names pass."""
    res = rigctl("take", "check", str(ideal))
    assert res.returncode == 0, res.stderr


# ---- calibration files ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def real(module_tmp: Callable[[str], Path]) -> Path:
    """A tiny take that needs rectifying, with its true calibration in truth/calibration.yaml."""
    return record_tiny(module_tmp("names-real"), "real", 1, "motion=false")


def misnamed_calibration(real: Path, tmp_path: Path, old: str, new: str) -> Path:
    """The take's true calibration with camera ``old`` named ``new`` (order kept)."""
    cal: dict[str, Any] = yaml.safe_load((real / "truth" / "calibration.yaml").read_text(encoding="utf-8"))
    cal["cameras"] = _renamed(cal["cameras"], old, new)
    path = tmp_path / "calibration.yaml"
    path.write_text(yaml.safe_dump(cal, sort_keys=False, allow_unicode=True), encoding="utf-8")
    return path


@pytest.mark.parametrize("verb", ["rectify", "usd"])
@pytest.mark.parametrize(("name", "right"), MISSPELT, ids=IDS)
def test_a_calibration_camera_written_another_way_is_refused_naming_the_right_name(
    real: Path, tmp_path: Path, name: str, right: str, verb: str
) -> None:
    """CAMERA_NAME matched Python's \\d, so a calibration took r٢c1 as the camera at row 2, column 1, and r01c0
    as a camera of its own beside r1c0; both are refused on their line now, naming the name to use."""
    cal = misnamed_calibration(real, tmp_path, right, name)
    out = tmp_path / ("r" if verb == "rectify" else "stage.usda")
    cmd = ["rectify", str(real), "--calibration", str(cal)] if verb == "rectify" else ["usd", str(cal)]
    res = rigctl(*cmd, "--out", str(out))
    one_line(res, EXIT_BAD_INPUT, f"{cal}:{key_line(cal, 'cameras', name)}: cameras:", f"camera name {name} is written")
    assert f"name it {right}" in res.stderr
    assert not out.exists() or not any(p.is_file() for p in out.rglob("*"))


# ---- the command line --------------------------------------------------------------------------------------------
NOT_NAMES = ["../r1c1", "r1c1/../r1c0", "/tmp/r1c1", "r1c1\n", "r1c1 ", ""]


def _command(verb: str, ideal: Path, out: Path, option: list[str]) -> list[str]:
    if verb == "depth":
        return ["depth", str(ideal), "--out", str(out), "--preset", "fast", *option]
    if verb == "process":
        return ["process", str(ideal), "--out", str(out), "--workers", "1", *option]
    if verb == "render":
        disparity = str(ideal / "truth" / "disparity")
        return ["render", str(ideal), "--disparity", disparity, "--leave-one-out", "--json", *option]
    if verb == "bench":
        return ["bench", "depth", "--size", "64x48", *option]
    if verb == "tally":
        return ["tally", "sim-3x3", *option]
    return ["control", "sim-3x3", "--gain", "2", *option]


VERBS = ["depth", "process", "render", "bench", "control", "tally"]
OPTION = {"control": "--camera", "tally": "--program"}


@pytest.mark.parametrize("verb", VERBS)
@pytest.mark.parametrize(("name", "right"), MISSPELT, ids=IDS)
def test_a_camera_option_written_another_way_names_the_right_name(
    ideal: Path, tmp_path: Path, verb: str, name: str, right: str
) -> None:
    """--cameras r01c0 was looked up among the take's cameras and not found ('no camera r01c0 in the grid'),
    as if the camera were not there: the option is held to the name's one spelling, naming r1c0."""
    option = [OPTION.get(verb, "--cameras"), name]
    res = rigctl(*_command(verb, ideal, tmp_path / "out", option))
    one_line(res, EXIT_USAGE, f"argument {option[0]}: {name} is written with", f"name it {right}")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("verb", VERBS)
@pytest.mark.parametrize("name", NOT_NAMES)
def test_a_camera_option_that_is_a_path_is_refused_before_anything_is_read(
    ideal: Path, tmp_path: Path, verb: str, name: str
) -> None:
    """A path given as a camera is refused as no camera name while the command line is read (a newline in it
    split the error over two lines)."""
    option = [OPTION.get(verb, "--cameras"), name]
    res = rigctl(*_command(verb, ideal, tmp_path / "out", option))
    one_line(res, EXIT_USAGE, f"argument {option[0]}: {name!r} is not a camera name r{{row}}c{{col}}")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("name", "right"), MISSPELT, ids=IDS)
def test_a_sim_setting_naming_a_camera_another_way_names_the_right_name(tmp_path: Path, name: str, right: str) -> None:
    """--sim drops.r01c0=[1] passed the name check and was then 'no camera r01c0' of the rig."""
    sim = f"drops.{name}=[1]"
    res = rigctl("record", "sim-3x3", "--take", "t", "--frames", "1", "--out", str(tmp_path), "--sim", sim)
    one_line(res, EXIT_USAGE, f"--sim drops: {name} is written with", f"name it {right}")
    assert not (tmp_path / "t").exists()


# ---- images to calibrate from --------------------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "right"), [("r0c01", "r0c1"), ("r٠c1", "r0c1")])
def test_calibration_images_of_a_camera_written_another_way_are_refused(
    real: Path, tmp_path: Path, name: str, right: str
) -> None:
    """A folder of frame sets <frame>/<camera>.png took r0c01.png as a camera r0c01 and went on to calibrate it
    (toward a calibration naming a camera as no grid folder, rig or take does); refused before any image is read."""
    folder = tmp_path / "views"
    (folder / "000000").mkdir(parents=True)
    export = rigctl("take", "export", str(real), "--out", str(tmp_path / "export"))
    assert export.returncode == 0, export.stderr
    for png in (tmp_path / "export" / "000000").glob("*.png"):
        png.rename(folder / "000000" / f"{name if png.stem == right else png.stem}.png")
    res = rigctl("calibrate", str(folder), "--out", str(tmp_path / "c.yaml"), timeout=300)
    one_line(res, EXIT_BAD_INPUT, f"{folder}: camera {name}", f"name it {right}")
    assert not (tmp_path / "c.yaml").exists()


@pytest.mark.parametrize("name", ["../../r1c0", "r1c0/..", "/tmp/r1c0", "r1c0\n", "r1c0\0"])
@pytest.mark.parametrize("verb", ["rectify", "usd"])
def test_a_calibration_camera_named_as_a_path_is_refused(real: Path, tmp_path: Path, name: str, verb: str) -> None:
    """A calibration's camera names become USD prim names and are matched to a take's file names: no path, no
    NUL, and no trailing newline (CAMERA_NAME's '$' matched before one, so 'r1c0\\n' was read as a camera)."""
    cal = misnamed_calibration(real, tmp_path, "r1c0", name)
    out = tmp_path / ("r" if verb == "rectify" else "stage.usda")
    cmd = ["rectify", str(real), "--calibration", str(cal)] if verb == "rectify" else ["usd", str(cal)]
    res = rigctl(*cmd, "--out", str(out))
    one_line(res, EXIT_BAD_INPUT, f"{cal}:", f"camera name {name!r} is not r{{row}}c{{col}}")
    assert not out.exists() or not any(p.is_file() for p in out.rglob("*"))
