"""``rigctl take check`` holds the sidecars editorial reads to the take: ``log.csv`` (what each camera delivered
and lost) and the Avid ALE (one clip per camera). Before, a hand edit or a sidecar copied from another take
passed as ok (exit 0). Each problem is one error line naming the file, the line and the field."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import pytest
from hostile_support import SIM_RIG, write_yaml  # type: ignore[import-not-found]
from reliab_support import copy_take, edit_manifest, record_tiny, rigctl  # type: ignore[import-not-found]

from rigctl.take.sidecars import NOT_WRITTEN
from rigctl.timecode import Timecode


@pytest.fixture(scope="module")
def dropping(module_tmp: Callable[[str], Path]) -> Path:
    """A tiny take (recorded with the simulator's defaults, motion on) in which r1c1 drops two frames."""
    return record_tiny(module_tmp("sidecars"), "t", 6, "drops.r1c1=[5,7]")


def _edit(path: Path, sep: str, line: int, column: int, value: str) -> None:
    rows = [ln.split(sep) for ln in path.read_text().split("\n")]
    rows[line - 1][column] = value
    path.write_text("\n".join(sep.join(r) for r in rows))


def _error(take: Path) -> str:
    res = rigctl("take", "check", str(take))
    assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, res.stderr
    return errors[0]


def test_the_recorders_own_sidecars_hold(dropping: Path) -> None:
    assert (dropping / "log.csv").is_file() and (dropping / "t.ale").is_file()
    res = rigctl("take", "check", str(dropping))
    assert res.returncode == 0, res.stderr


# line numbers: log.csv's header is line 1, r1c1 (the fifth camera) line 6; the ALE's first clip is line 10
# (file, line, column, value), what the error says. log.csv's header is line 1, r1c1 (the fifth camera) line 6;
# the ALE's first clip is line 10. A value None: End one frame later than the clip's frames reach
EDITS: dict[str, tuple[tuple[str, int, int, str | None], str]] = {
    "log frames": (("log.csv", 6, 2, "6"), "line 6: r1c1 frames '6', take.yaml and the index say '4'"),
    "log a loss hidden": (("log.csv", 6, 5, "0"), "line 6: r1c1 source_drops '0', take.yaml and the index say '2'"),
    "log first sequence": (("log.csv", 2, 3, "3"), "line 2: r0c0 first_sequence '3'"),
    "log bytes": (("log.csv", 2, 9, "1"), "line 2: r0c0 bytes '1'"),
    "log an end that was not": (("log.csv", 2, 10, "signal lost"), "line 2: r0c0 ended_early 'signal lost'"),
    "log cameras swapped": (("log.csv", 2, 0, "r0c1"), "line 2: camera 'r0c1' is not r0c0"),
    "log a header renamed": (("log.csv", 1, 2, "count"), "line 1: header"),
    "ale frames": (("t.ale", 14, 6, "6"), "line 14: r1c1 Frames '6', take.yaml says '4'"),
    "ale drops": (("t.ale", 14, 7, "0"), "line 14: r1c1 Drops '0', take.yaml says '2'"),
    "ale a clip of another take": (("t.ale", 10, 0, "u_r0c0"), "line 10: r0c0 Name 'u_r0c0', take.yaml says 't_r0c0'"),
    "ale an end a frame late": (("t.ale", 10, 3, None), "line 10: r0c0 Start"),
    "ale no timecode": (("t.ale", 10, 3, "25:99:00:00"), "line 10: r0c0: timecode 25:99:00:00 does not exist"),
    "ale another frame rate": (("t.ale", 4, 1, "30"), "FPS '30', the take's is '25'"),
    # Start and End both a frame late: the span holds, the clip is not where the camera's frames are
    "ale a clip moved": (("t.ale", 10, 2, "moved"), "line 10: r0c0 Start"),
}


@pytest.mark.parametrize("how", EDITS)
def test_take_check_holds_log_csv_and_the_ale_to_the_take(dropping: Path, tmp_path: Path, how: str) -> None:
    take = copy_take(dropping, tmp_path / "t")
    (name, line, column, value), said = EDITS[how]
    path, sep = take / name, "," if name.endswith(".csv") else "\t"
    if value is None:
        value = str(Timecode.parse(path.read_text().split("\n")[line - 1].split("\t")[3], 25) + 1)
    if value == "moved":
        row = path.read_text().split("\n")[line - 1].split("\t")
        _edit(path, sep, line, 3, str(Timecode.parse(row[3], 25) + 1))
        value = str(Timecode.parse(row[2], 25) + 1)
    _edit(path, sep, line, column, value)
    error = _error(take)
    assert f"{path}:" in error and said in error, error


def test_a_log_csv_missing_a_camera_is_an_error(dropping: Path, tmp_path: Path) -> None:
    take = copy_take(dropping, tmp_path / "t")
    lines = (take / "log.csv").read_text().splitlines()
    (take / "log.csv").write_text("\n".join(lines[:-1]) + "\n")
    assert "8 camera rows, take.yaml has 9 cameras" in _error(take)
    (take / "log.csv").write_text("\n".join(lines) + "\n")  # as the recorder wrote it
    assert rigctl("take", "check", str(take)).returncode == 0


def _warnings(take: Path) -> list[str]:
    res = rigctl("take", "check", str(take))
    assert res.returncode == 0 and "error:" not in res.stderr, res.stderr
    return [ln for ln in res.stderr.splitlines() if ln.startswith("warning:")]


def test_a_sidecar_missing_from_a_take_that_ended_is_a_warning_each(dropping: Path, tmp_path: Path) -> None:
    """Before, a take that had lost its sidecars (a copy that left them behind) passed as ok without a word; its
    frames are all there, so each missing one is a warning naming it, and the exit stays 0."""
    assert _warnings(dropping) == []
    take = copy_take(dropping, tmp_path / "t")
    (take / "log.csv").unlink()
    (warning,) = _warnings(take)
    assert f"{take / 'log.csv'}: missing" in warning, warning
    (take / "sets.csv").unlink()
    (take / "t.ale").unlink()
    said = _warnings(take)
    assert [w.split(": ")[1] for w in said] == [str(take / n) for n in ("sets.csv", "log.csv", "t.ale")], said
    edit_manifest(take, lambda m: m["frame_sets"].update(file="log.csv"))  # a name another sidecar has
    assert len(_warnings(take)) == 2, "log.csv warned of twice"
    # a take.yaml without frame sets (edited, or from elsewhere): no sets.csv to look for, but the camera log
    # and the ALE are still the recorder's (session 28's review: no warning at all before)
    edit_manifest(take, lambda m: m.pop("frame_sets"))
    said = _warnings(take)
    assert [w.split(": ")[1] for w in said] == [str(take / n) for n in ("log.csv", "t.ale")], said


def test_a_take_that_never_had_sidecars_is_not_warned_of_them(dropping: Path, tmp_path: Path) -> None:
    """No sidecar is looked for where the recorder wrote none: a rectified take (``rigctl rectify`` keeps the
    frame sets in its manifest and writes no sidecar), a recording that did not end, or one whose notes say why
    they could not be written (the recorder's own note, ``take.build.finalise``)."""
    rectified = tmp_path / "rectified"
    calibration = dropping / "truth" / "calibration.yaml"
    res = rigctl("rectify", str(dropping), "--calibration", str(calibration), "--out", str(rectified))
    assert res.returncode == 0, res.stderr
    assert not (rectified / "sets.csv").exists() and _warnings(rectified) == []
    for status, notes in (("recording", []), ("complete", [f"{NOT_WRITTEN}: No space left on device"])):
        take = copy_take(dropping, tmp_path / status)
        for name in ("sets.csv", "log.csv", "t.ale"):
            (take / name).unlink()
        edit_manifest(take, lambda m, s=status, n=notes: m.update(status=s, notes=n))
        assert not [w for w in _warnings(take) if "missing" in w], status


def test_sidecars_other_tools_rewrote_with_crlf_or_a_trailing_blank_line_still_hold(
    dropping: Path, tmp_path: Path
) -> None:
    take = copy_take(dropping, tmp_path / "t")
    ale, log = take / "t.ale", take / "log.csv"
    ale.write_bytes(ale.read_bytes().replace(b"\n", b"\r\n"))
    log.write_bytes(log.read_bytes() + b"\r\n")
    res = rigctl("take", "check", str(take))
    assert res.returncode == 0, res.stderr


def test_a_drop_frame_take_passes_and_a_clip_relabelled_non_drop_does_not(tmp_path: Path) -> None:
    """At 29.97 fps the take's timecode is drop-frame (HH:MM:SS;FF), and its ALE holds. (A camera's own timecode
    may be non-drop at 29.97: each label is read as its separator says; the simulator's frames carry none.)"""
    rig = dict(SIM_RIG, format={**SIM_RIG["format"], "width_px": 96, "height_px": 54, "fps": 29.97})
    write_yaml(tmp_path / "drop.yaml", rig)
    res = rigctl(
        "record", str(tmp_path / "drop.yaml"), "--take", "d", "--frames", "4", "--out", str(tmp_path), "--force",
        "--sim", "deterministic=true",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    take, ale = tmp_path / "d", tmp_path / "d" / "d.ale"
    row = ale.read_text().split("\n")[9].split("\t")
    assert ";" in row[2] and "FPS\t29.97" in ale.read_text()
    assert rigctl("take", "check", str(take)).returncode == 0
    # relabelled non-drop, the clip no longer starts where the take's drop-frame timecode does
    _edit(ale, "\t", 10, 2, row[2].replace(";", ":"))
    assert "r0c0 Start" in _error(take)


@pytest.mark.parametrize("kind", ["a FIFO", "a device", "too large", "not UTF-8"])
@pytest.mark.parametrize("name", ["log.csv", "t.ale"])
def test_a_sidecar_that_is_no_file_or_no_text_is_one_problem_without_waiting(
    dropping: Path, tmp_path: Path, kind: str, name: str
) -> None:
    take = copy_take(dropping, tmp_path / "t")
    path = take / name
    path.unlink()
    if kind == "a FIFO":
        os.mkfifo(path)
    elif kind == "a device":
        path.symlink_to("/dev/zero")
    elif kind == "too large":
        path.write_text("x" * 10_000_000)
    else:
        path.write_bytes(b"camera,\xff\n")
    res = rigctl("take", "check", str(take), timeout=60)
    assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
    error = _error(take)
    assert error.startswith(f"error: {path}:"), error
    if kind == "not UTF-8":
        assert "byte 7: " in error and "not UTF-8" in error, error


def test_a_take_name_that_is_a_path_is_not_followed_to_an_ale(dropping: Path, tmp_path: Path) -> None:
    """take.yaml's take names the ALE; a name that is a path is not a file of the take's to open."""
    take = copy_take(dropping, tmp_path / "t")
    (tmp_path / "outside.ale").write_text("not an ALE\n")
    edit_manifest(take, lambda m: m.update(take="../outside"))
    res = rigctl("take", "check", str(take))
    assert "outside.ale" not in res.stderr, res.stderr


SIDECARS_PAST_A_LIMIT = """
import resource, signal, sys
from pathlib import Path
from rigctl.errors import OutputError
from rigctl.take import sidecars
from rigctl.take.accounting import CameraStats
from rigctl.take.framesets import FrameSet
from rigctl.timecode import Timecode

folder = Path(sys.argv[1])
names = [f"r{i}c0" for i in range(300)]
stats = {n: CameraStats(n, written=[(s, 40_000_000 * s) for s in range(3)], bytes_written=12345) for n in names}
sets = [FrameSet(number=k, time_ns=40_000_000 * k, members={n: k % 3 for n in names}, spread_ns=0) for k in range(12)]
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG, as on a full disk
resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
for write in (
    lambda: sidecars.write_log_csv(folder / "log.csv", names, dict.fromkeys(names, "/dev/video0"), stats),
    lambda: sidecars.write_sets_csv(folder / "sets.csv", sets, names, stats, Timecode(0, 25)),
):
    try:
        write()
    except OutputError as exc:
        print(exc)
"""


def test_a_sidecar_that_cannot_be_written_whole_is_not_left_torn(tmp_path: Path) -> None:
    """sets.csv and log.csv were written in place: a take ended by a kill or a full disk kept a torn one that
    editorial would read as the take's. Now each is whole at its name or absent (the recorder notes the loss)."""
    import subprocess
    import sys

    res = subprocess.run(
        [sys.executable, "-c", SIDECARS_PAST_A_LIMIT, str(tmp_path)], capture_output=True, text=True, timeout=60
    )
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert len(lines) == 2 and "log.csv" in lines[0] and "sets.csv" in lines[1], res.stdout
    assert list(tmp_path.iterdir()) == []  # neither a torn file nor a temporary one
