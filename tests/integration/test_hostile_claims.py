"""Files from others that claim what cannot be (h-check): a rotation that is none, sequence numbers and frame-set
rows that disagree with the take, camera names written two ways, boards no detector can use, two grids in one
folder. Each is one line naming the file and the field, and a documented exit code; never exit 0."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from conftest import SHARED
from hostile_support import SIM_RIG, one_line, write_yaml  # type: ignore[import-not-found]
from reliab_support import copy_take, edit_manifest, record_tiny, rigctl  # type: ignore[import-not-found]

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


# ---- rectification.R: a rotation -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ideal(module_tmp: Callable[[str], Path]) -> Path:
    """An ideal tiny take: rectified as recorded, its manifest holding rectification.R."""
    return record_tiny(module_tmp("claims-ideal"), "ideal", 1, "ideal=true", "motion=false")


def _rotated(R: list[list[float]], M: list[list[float]]) -> list[list[float]]:
    return (np.asarray(M) @ np.asarray(R)).tolist()  # type: ignore[no-any-return]


NOT_ROTATIONS = {
    "scaled": [[2, 0, 0], [0, 2, 0], [0, 0, 2]],
    "mirrored": [[1, 0, 0], [0, 1, 0], [0, 0, -1]],
    "sheared": [[1, 0.01, 0], [0, 1, 0], [0, 0, 1]],
    "singular": [[1, 0, 0], [1, 0, 0], [0, 0, 1]],
}


@pytest.mark.parametrize("verb", ["info", "depth"])
@pytest.mark.parametrize("how", NOT_ROTATIONS)
def test_a_rectification_that_is_no_rotation_is_one_line(ideal: Path, tmp_path: Path, how: str, verb: str) -> None:
    """rectification.R was checked to be 3x3 and finite only: scaled, mirrored or sheared, it was read, exit 0."""
    take = copy_take(ideal, tmp_path / "t")
    edit_manifest(
        take, lambda m: m["rectification"].__setitem__("R", _rotated(m["rectification"]["R"], NOT_ROTATIONS[how]))
    )
    cmd = (
        ["take", "info", str(take)]
        if verb == "info"
        else ["depth", str(take), "--out", str(tmp_path / "d"), "--preset", "fast"]
    )
    one_line(rigctl(*cmd), EXIT_BAD_INPUT, f"{take / 'take.yaml'}:", "rectification.R", "is not a rotation")
    assert not (tmp_path / "d").exists() or not any((tmp_path / "d").rglob("*.exr"))


def test_a_rotation_written_in_float32_by_another_tool_is_read(ideal: Path, tmp_path: Path) -> None:
    take = copy_take(ideal, tmp_path / "t")
    tilt = cv2.Rodrigues(np.array([0.01, -0.02, 0.005]))[0]  # not the identity, so float32 rounding shows
    edit_manifest(
        take,
        lambda m: m["rectification"].__setitem__(
            "R", [[float(np.float32(v)) for v in row] for row in _rotated(m["rectification"]["R"], tilt.tolist())]
        ),
    )
    res = rigctl("take", "info", str(take))
    assert res.returncode == 0, res.stderr


# ---- grid folders: one connected grid ------------------------------------------------------------------------------
def grid_folder(folder: Path, cameras: list[tuple[int, int]]) -> Path:
    """A grid folder of 64x48 pictures at ``cameras`` (row, col), spacing 1, focal 100 px."""
    folder.mkdir()
    rng = np.random.default_rng(1)
    picture = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    for row, col in cameras:
        cv2.imwrite(str(folder / f"r{row}c{col}.png"), np.roll(picture, -3 * col, axis=1))
    (folder / "grid.yaml").write_text("spacing_x: 1\nspacing_y: 1\nfocal_px: 100\n")
    return folder


def test_two_grids_far_apart_in_one_folder_are_refused_naming_both(tmp_path: Path) -> None:
    """r0c0..r2c2 and r100c100..r102c102 in one folder: each camera shares views with its own 3x3, so no camera
    was alone, and the two grids were estimated as one (one range, one report), exit 0."""
    near = [(r, c) for r in range(3) for c in range(3)]
    grid = grid_folder(tmp_path / "g", [*near, *((r + 100, c + 100) for r, c in near)])
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=120)
    one_line(
        res, EXIT_BAD_INPUT, f"{grid}: the pictures form 2 grids that share no view",
        "r0c0..r2c2 (9 cameras)", "r100c100..r102c102 (9 cameras)",
    )  # fmt: skip
    assert not (tmp_path / "d").exists() or not any((tmp_path / "d").rglob("*.exr"))


def test_a_chain_of_cameras_that_share_views_pairwise_is_one_grid(tmp_path: Path) -> None:
    """r0c0 and r0c120 share no view (120 spacings on 64 px pictures), but each shares one with the camera
    40 columns beside it: one grid, read."""
    grid = grid_folder(tmp_path / "g", [(0, 0), (0, 40), (0, 80), (0, 120)])
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=300)
    assert res.returncode == 0, res.stderr
    assert len(list((tmp_path / "d").glob("*.exr"))) == 4


def _groups_by_pairs(cams: list[tuple[int, int]], size: tuple[int, int], ratio: float) -> int:
    """How many groups the cameras form, every pair compared (the definition; quadratic)."""
    group = list(range(len(cams)))

    def find(k: int) -> int:
        while group[k] != k:
            k = group[k]
        return k

    w, h = size
    for a, (ra, ca) in enumerate(cams):
        for b, (rb, cb) in enumerate(cams[:a]):
            if abs(ca - cb) / w < 1 and abs(ra - rb) * ratio / h < 1:
                group[find(a)] = find(b)
    return len({find(k) for k in range(len(cams))})


@pytest.mark.parametrize("seed", range(40))
def test_grid_groups_match_every_pair_compared(seed: int) -> None:
    """The cell-by-cell grouping (linear in the cameras) agrees with comparing every pair."""
    from rigctl.depth.grid_folder import _refuse_apart
    from rigctl.errors import RigFileError

    rng = np.random.default_rng(seed)
    size = (int(rng.integers(8, 40)), int(rng.integers(8, 40)))
    ratio = float(rng.choice([0.5, 1.0, 1.7]))
    spots = {(int(r), int(c)) for r, c in rng.integers(0, 120, (int(rng.integers(2, 30)), 2))}
    cams = sorted(spots)
    files = [Path(f"/g/r{r}c{c}.png") for r, c in cams]
    groups = _groups_by_pairs(cams, size, ratio)
    if groups == 1:
        _refuse_apart(files, size, ratio, None)
    else:
        with pytest.raises(RigFileError, match=r"shares no view|grids that share no view"):
            _refuse_apart(files, size, ratio, None)


def test_grid_grouping_is_linear_in_the_cameras() -> None:
    """40,000 cameras (200x200 positions, each picture 8x8: every camera in a cell of its own) in about a second."""
    import time

    from rigctl.depth.grid_folder import _refuse_apart

    files = [Path(f"/g/r{r}c{c}.png") for r in range(200) for c in range(200)]
    start = time.perf_counter()
    _refuse_apart(files, (8, 8), 1.0, None)
    assert time.perf_counter() - start < 10


# ---- a take's sequence numbers and sets.csv ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def dropping(module_tmp: Callable[[str], Path]) -> Path:
    """A tiny take in which r1c1 drops two frames: sets.csv has incomplete rows and blank cells."""
    return record_tiny(module_tmp("claims-drops"), "t", 6, "motion=false", "drops.r1c1=[5,7]")


def _camera(name: str, **values: object) -> Callable[[dict[str, Any]], None]:
    return lambda m: m["cameras"][name].update(values)


@pytest.mark.parametrize(
    ("edit", "said"),
    [
        (_camera("r0c0", first_sequence="4"), "cameras.r0c0.first_sequence"),
        (_camera("r0c0", first_sequence=4.0), "cameras.r0c0.first_sequence"),
        (_camera("r0c0", first_sequence=-1), "cameras.r0c0.first_sequence"),
        (_camera("r0c0", first_sequence=1 << 64), "cameras.r0c0.first_sequence"),
        (_camera("r0c0", first_sequence=9, last_sequence=4), "first_sequence 9 is after last_sequence 4"),
        (_camera("r0c0", first_sequence=None), "give both or neither"),
        (_camera("r0c0", first_sequence=4, last_sequence=6), "fewer than the 6 of frames"),
        # within the rules alone, but not the index's: its records run from 4 to 9
        (_camera("r0c0", first_sequence=0, last_sequence=100), "disagree with r0c0.index"),
        (_camera("r0c0", first_sequence=5, last_sequence=10), "disagree with r0c0.index"),
        (lambda m: m["frame_sets"].update(count=7), "count 7 is not complete 4 plus the 2 incomplete"),
        (lambda m: m["frame_sets"].update(count="6"), "frame_sets.count"),
        (lambda m: m["frame_sets"]["incomplete"][1].update(number=1), "set numbers must be distinct"),
        (lambda m: m["frame_sets"].update(file="../../../etc/passwd"), "is not a file name beside take.yaml"),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
@pytest.mark.parametrize("verb", ["info", "export"])
def test_sequence_numbers_and_frame_set_counts_that_cannot_be_are_one_line(
    dropping: Path, tmp_path: Path, edit: Callable[[dict[str, Any]], None], said: str, verb: str
) -> None:
    """first_sequence and last_sequence were taken as any number (or text), each alone, in any order, whatever the
    index held; frame_sets' counts and file as written. Every reader refuses them, naming the field."""
    take = copy_take(dropping, tmp_path / "t")
    edit_manifest(take, edit)
    extra = ["--out", str(tmp_path / "out")] if verb == "export" else []
    one_line(rigctl("take", verb, str(take), *extra), EXIT_BAD_INPUT, f"{take / 'take.yaml'}:", said)
    res = rigctl("take", "check", str(take))
    assert res.returncode == 1 and said in res.stderr and "Traceback" not in res.stderr, res.stderr


def _rows(take: Path, edit: Callable[[list[list[str]]], None]) -> None:
    path = take / "sets.csv"
    rows = [line.split(",") for line in path.read_text().splitlines()]
    edit(rows)
    path.write_text("".join(",".join(r) + "\n" for r in rows))


def _cell(row: int, column: int, value: str) -> Callable[[list[list[str]]], None]:
    return lambda rows: rows[row].__setitem__(column, value)


def _unlisted(rows: list[list[str]]) -> None:
    """Set 0 without r0c0's frame, marked incomplete: an incomplete set take.yaml does not list."""
    rows[1][3], rows[1][5] = "0", ""


SETS_EDITS = {
    "a row twice": (lambda rows: rows.insert(2, rows[1]), "line 3: set '0' is not 1"),
    "a row left out": (lambda rows: rows.pop(), "5 frame sets, take.yaml frame_sets.count claims 6"),
    "a set numbered 1.0": (_cell(2, 0, "1.0"), "line 3: set '1.0' is not 1"),
    "a sequence of no frame": (_cell(1, 5, "99"), "line 2: r0c0 '99' is not a sequence number of r0c0.index"),
    "a sequence in text": (_cell(1, 5, "four"), "line 2: r0c0 'four' is not a sequence number"),
    "a frame in two sets": (_cell(2, 5, "4"), "line 3: r0c0 4: sequence 4 after 4"),
    "complete that is not": (_cell(2, 3, "1"), "line 3: complete '1', but 1 camera(s) have no frame"),
    "an incomplete set not listed": (_unlisted, "line 2: cameras missing ['r0c0'], take.yaml frame_sets.incomplete"),
    "a camera left blank": (_cell(1, 9, ""), "line 2: complete '1', but 1 camera(s)"),
    "cameras swapped in the header": (_cell(0, 5, "r0c1"), "line 1: header"),
    "a row cut short": (lambda rows: rows[1].pop(), "line 2: 13 fields, the header has 14"),
    "a timecode that is none": (_cell(1, 1, "25:99:00:00"), "line 2: timecode '25:99:00:00'"),
    "a time that is none": (_cell(1, 2, "1e9"), "line 2: time_ns '1e9' is not a whole number"),
    "a spread of NaN": (_cell(1, 4, "nan"), "line 2: spread_us 'nan'"),
    "an unclosed quote": (_cell(1, 4, '"1'), "line"),
}


@pytest.mark.parametrize("how", SETS_EDITS)
def test_take_check_holds_sets_csv_to_the_take(dropping: Path, tmp_path: Path, how: str) -> None:
    """sets.csv (frame sets as editorial reads them) was never read back: rows twice or missing, sequence numbers
    of no frame, a frame in two sets, complete flags that lie; take check said ok, exit 0. Readers assemble frame
    sets from the indexes and do not read it, so take info still reads the take."""
    take = copy_take(dropping, tmp_path / "t")
    edit, said = SETS_EDITS[how]
    _rows(take, edit)
    res = rigctl("take", "check", str(take))
    assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and f"{take / 'sets.csv'}:" in errors[0] and said in errors[0], res.stderr
    assert rigctl("take", "info", str(take)).returncode == 0


@pytest.mark.parametrize("kind", ["a FIFO", "a device", "too large"])
def test_a_sets_csv_that_is_no_file_or_too_large_is_one_problem_without_waiting(
    dropping: Path, tmp_path: Path, kind: str
) -> None:
    take = copy_take(dropping, tmp_path / "t")
    sets = take / "sets.csv"
    sets.unlink()
    if kind == "a FIFO":
        os.mkfifo(sets)
    elif kind == "a device":
        sets.symlink_to("/dev/zero")
    else:
        sets.write_text("x" * 10_000_000)
    res = rigctl("take", "check", str(take), timeout=60)
    assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
    assert f"error: {sets}: frame-set file" in res.stderr, res.stderr


def test_takes_as_recorded_and_rectified_pass_take_check(dropping: Path, tmp_path: Path) -> None:
    """The recorder's own sets.csv and sequence numbers hold; a rectified take (no sets.csv) too."""
    res = rigctl("take", "check", str(dropping))
    assert res.returncode == 0, res.stderr
    truth = dropping / "truth" / "calibration.yaml"
    res = rigctl("rectify", str(dropping), "--calibration", str(truth), "--out", str(tmp_path / "r"))
    assert res.returncode == 0, res.stderr
    res = rigctl("take", "check", str(tmp_path / "r"))
    assert res.returncode == 0, res.stderr
