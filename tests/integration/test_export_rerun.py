"""``rigctl take export`` into an --out used before: the folder ends up describing exactly this run. The earlier
run's ``export.json`` (with its damaged frames) and its frame or camera folders that this run does not write
were kept, so a second export into one folder mixed two runs. Now a run replaces the export it finds (only the
files its record lists: a user's file stays), a run killed at any instant (SIGKILL, tests/fault_runner.py) and
run again leaves what a clean run leaves, and folders of exports that listed nothing are refused in one line."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from hostile_support import one_line  # type: ignore[import-not-found]
from reliab_support import make_tiny, published, rigctl  # type: ignore[import-not-found]

from rigctl.errors import EXIT_DAMAGED, EXIT_USAGE
from rigctl.publish import PARTIAL_SUFFIX, TEMP_SUFFIX

RUNNER = Path(__file__).resolve().parents[1] / "fault_runner.py"
CAMS = [f"r{r}c{c}" for r in range(3) for c in range(3)]


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    return make_tiny(module_tmp("rerun"))[0]


def clean(take: Path, root: Path, *options: str) -> dict[str, bytes]:
    """What a run with ``options`` leaves in a folder of its own."""
    out = root / "clean"
    res = rigctl("take", "export", str(take), "--out", str(out), *options)
    assert res.returncode == 0, res.stderr
    return published(out)


def damaged_copy(take: Path, dest: Path) -> Path:
    """``take`` copied with one frame of r1c1 failing its checksum (frame set 1)."""
    import shutil

    shutil.copytree(take, dest)
    ess = dest / yaml.safe_load((dest / "take.yaml").read_text())["cameras"]["r1c1"]["essence"]
    at = ess.stat().st_size // 3 + 100
    with open(ess, "r+b") as f:
        f.seek(at)
        old = f.read(4)
        f.seek(at)
        f.write(bytes(b ^ 0xFF for b in old))
    return dest


def test_a_second_export_replaces_the_first_and_keeps_the_users_published(take: Path, tmp_path: Path) -> None:
    """The first run (a damaged copy, --skip-damaged) listed r1c1's frame in export.json and wrote frame sets
    0-2; the second (the good take, frame set 0 as EXR) used to leave that list and frame sets 1 and 2 beside
    its own pictures. Now the folder holds exactly what a clean run of the second leaves, and the user's files."""
    out = tmp_path / "out"
    res = rigctl("take", "export", str(damaged_copy(take, tmp_path / "bad")), "--out", str(out), "--skip-damaged")
    assert res.returncode == EXIT_DAMAGED, res.stderr
    assert json.loads((out / "export.json").read_text())["skipped_damaged"], "the first run lists its damage"
    (out / "notes.txt").write_text("mine")
    (out / "000002" / "notes.txt").write_text("mine too")  # in a frame folder of the first run's
    res = rigctl("take", "export", str(take), "--out", str(out), "--frames", "0", "--format", "exr")
    assert res.returncode == 0, res.stderr
    mine = published(out)
    assert mine.pop("notes.txt") == b"mine" and mine.pop("000002/notes.txt") == b"mine too"
    assert mine == clean(take, tmp_path, "--frames", "0", "--format", "exr")
    record = json.loads(mine["export.json"])
    assert record["complete"] and record["skipped_damaged"] == []
    assert record["files"] == [f"000000/{c}.exr" for c in CAMS]
    assert not (out / "000001").exists()  # a frame folder only ours: gone with its pictures


def test_a_rerun_that_leaves_out_a_damaged_frame_removes_the_earlier_picture_of_it(
    take: Path, tmp_path: Path
) -> None:
    """A clean export, then the same export of a damaged copy with --skip-damaged: r1c1's picture of frame set 1
    (which this run did not write) is not left behind from the first run."""
    out = tmp_path / "out"
    assert rigctl("take", "export", str(take), "--out", str(out)).returncode == 0
    bad = damaged_copy(take, tmp_path / "bad")
    res = rigctl("take", "export", str(bad), "--out", str(out), "--skip-damaged")
    assert res.returncode == EXIT_DAMAGED, res.stderr
    assert not (out / "000001" / "r1c1.png").exists() and (out / "000001" / "r1c0.png").exists()
    reference = tmp_path / "reference"
    assert rigctl("take", "export", str(bad), "--out", str(reference), "--skip-damaged").returncode == EXIT_DAMAGED
    assert published(out) == published(reference)


RERUN = ("--frames", "1-2", "--format", "exr", "--layout", "sequence")
KILLS = [("replace", 1), ("unlink", 4), ("unlink", 20), ("replace", 8), ("replace", 14), ("fsync", 30), ("replace", 38)]


@pytest.mark.parametrize(("call", "nth"), KILLS, ids=[f"{c}-{n}" for c, n in KILLS])
def test_a_rerun_killed_in_the_middle_then_run_again_equals_a_clean_run(
    take: Path, tmp_path: Path, call: str, nth: int
) -> None:
    """A PNG export of every frame set, then an EXR sequence of frame sets 1-2 into the same folder, killed with
    SIGKILL at an exact system call (the record about to be published, the first run's files being removed,
    the new pictures being published): every file at its final name is whole, and the same command run again
    leaves exactly what a clean run leaves (no PNG of the first run, no temporary or staging file)."""
    out = tmp_path / "out"
    assert rigctl("take", "export", str(take), "--out", str(out)).returncode == 0
    argv = ["take", "export", str(take), "--out", str(out), *RERUN]
    killed = subprocess.run(
        [sys.executable, str(RUNNER), call, str(nth), "KILL", "--", *argv],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert killed.returncode == -9, (killed.returncode, killed.stderr)
    published(out)  # whole at every final name
    res = rigctl(*argv)
    assert res.returncode == 0, res.stderr
    assert published(out) == clean(take, tmp_path, *RERUN)
    assert not list(out.rglob(f"*{TEMP_SUFFIX}")) and not list(out.glob(f".*{PARTIAL_SUFFIX}"))


def test_folders_of_an_export_that_listed_nothing_are_refused_and_left_alone(take: Path, tmp_path: Path) -> None:
    """An older rigctl wrote no record of a clean export, and only the damaged frames in export.json: their files
    cannot be told from the user's, so a run on such a folder is refused in one line and nothing is removed."""
    out = tmp_path / "old"
    (out / "000007").mkdir(parents=True)
    (out / "000007" / "r0c0.png").write_bytes(b"kept")
    res = rigctl("take", "export", str(take), "--out", str(out))
    one_line(res, EXIT_USAGE, f"--out {out}: holds 000007/ but no export.json", "choose another --out")
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*")) == ["000007", "000007/r0c0.png"]
    for record in ({"take": "t", "images": 26, "skipped_damaged": []}, {"files": ["../../victim.png"]}, "not json"):
        (out / "export.json").write_text(record if isinstance(record, str) else json.dumps(record))
        res = rigctl("take", "export", str(take), "--out", str(out))
        one_line(res, EXIT_USAGE, f"{out / 'export.json'}: not a record of the files a take export wrote")
        assert (out / "000007" / "r0c0.png").read_bytes() == b"kept" and not (out / "000000").exists()
    other = tmp_path / "other"  # a folder of the user's with no frame or camera folder: exported into, kept
    other.mkdir()
    (other / "readme.txt").write_text("mine")
    assert rigctl("take", "export", str(take), "--out", str(other), "--frames", "0").returncode == 0
    assert (other / "readme.txt").read_text() == "mine" and len(list((other / "000000").iterdir())) == 9
