"""Take numbers of the shoot UI go on from the takes on disk, per scene and shot, over every destination."""

from __future__ import annotations

from pathlib import Path

import pytest

from rigctl.errors import ParameterError
from rigctl.take.names import check_take_name, next_take_name, next_take_number


def test_numbers_go_on_from_the_highest_take_of_that_scene_and_shot(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    for folder in (a / "S01-01-T01", a / "S01-01-T09", b / "S01-01-T03", a / "S01-02-T30", a / "S02-01-T40"):
        folder.mkdir(parents=True)
    (a / "S01-01-T99.txt").write_text("not a take")  # a name that only starts like a take
    (a / "S01-01-Tx").mkdir()
    assert next_take_number([a, b], "S01", "01") == 10
    assert next_take_name([a, b], "S01", "01") == "S01-01-T10"  # past two digits when the shoot gets there
    assert next_take_name([b], "S01", "01") == "S01-01-T04"
    assert next_take_name([a], "S01", "02") == "S01-02-T31"
    assert next_take_name([tmp_path / "missing"], "S03", "01") == "S03-01-T01"


def test_a_scene_that_would_escape_the_destination_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match="escape"):
        next_take_number([tmp_path], "../x", "01")


def test_a_take_still_being_recorded_or_cut_off_counts_for_the_next_number(tmp_path: Path) -> None:
    from rigctl.take.names import next_take_name

    (tmp_path / "S1-2-T03").mkdir()
    (tmp_path / ".S1-2-T07.rigctl-recording").mkdir()  # recorded under its hidden name until published
    (tmp_path / ".S1-2-T09.other").mkdir()
    assert next_take_name([tmp_path], "S1", "2") == "S1-2-T08"


def test_a_second_recording_of_a_name_being_recorded_is_refused_and_touches_nothing(tmp_path: Path) -> None:
    from rigctl.errors import TakeError
    from rigctl.take.plan import TakePlan
    from rigctl.take.staging import Staging

    first = Staging(TakePlan.spread("t", [tmp_path / "a", tmp_path / "b"], ["r0c0", "r0c1"]))
    first.create()
    (first.plan.folder / "take.yaml").write_text("being recorded\n")
    second = Staging(TakePlan.spread("t", [tmp_path / "a", tmp_path / "b"], ["r0c0", "r0c1"]))
    with pytest.raises(TakeError, match="another rigctl run is recording"):
        second.create()  # its recovery of leftovers must not take a live recording for one either
    assert (first.plan.folder / "take.yaml").read_text() == "being recorded\n"
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == [".t.rigctl-recording"]
    first.publish()
    assert (tmp_path / "a" / "t" / "take.yaml").exists() and (tmp_path / "b" / "t").is_dir()
    assert not list(tmp_path.rglob("*.rigctl-recording"))


def test_new_folders_are_removed_again_while_empty_and_nothing_else(tmp_path: Path) -> None:
    from rigctl.publish import NewFolders

    (tmp_path / "old").mkdir()
    made = NewFolders(tmp_path / "a" / "b", tmp_path / "old" / "c", tmp_path / "old", tmp_path / "a" / "e")
    for p in (tmp_path / "a" / "b", tmp_path / "old" / "c", tmp_path / "a" / "e" / "kept"):
        p.mkdir(parents=True)
    made.remove_empty()  # a/b goes, a stays (a/e holds something), old/c goes, old (there before) stays
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == ["a", "a/e", "a/e/kept", "old"]


def test_leftovers_are_never_published_nor_their_frames_removed(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """What killed recorders left (their locks free): one of another name is named in a warning and left as it
    is; one of the name holding a frame (indexed, or essence bytes before the first record) refuses the name;
    only one of the name without a frame is removed."""
    from rigctl.errors import TakeError
    from rigctl.take.index import RECORD_SIZE
    from rigctl.take.plan import TakePlan
    from rigctl.take.staging import Staging

    def killed(name: str, index: int, essence: int) -> Path:
        staging = Staging(TakePlan.spread(name, [tmp_path], ["r0c0"]))
        staging.create()
        cameras = staging.plan.camera_folders["r0c0"]
        cameras.mkdir(parents=True)
        (cameras / "r0c0.index").write_bytes(b"\1" * index)
        (cameras / "r0c0.essence").write_bytes(b"\2" * essence)
        staging.release()  # its lock goes with the process
        return staging.plan.folder

    indexed, unindexed, empty = killed("t", 2 * RECORD_SIZE, 100), killed("w", 0, 100), killed("e", 0, 0)
    files = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    u = Staging(TakePlan.spread("u", [tmp_path], ["r0c0"]))
    with caplog.at_level("WARNING"):
        u.create()
    said = " ".join(caplog.messages)
    assert "a recording of t that was cut off (2 frame(s)" in said and "a recording of w that was cut off (1 " in said
    assert "a recording of e that was cut off (0 frame(s), status: no manifest here); it holds no frame" in said
    u.discard()
    for name, folder in (("t", indexed), ("w", unindexed)):
        with pytest.raises(TakeError, match=f"{folder}: a recording of {name} that was cut off .*never publishes"):
            Staging(TakePlan.spread(name, [tmp_path], ["r0c0"])).create()
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == files
    e = Staging(TakePlan.spread("e", [tmp_path], ["r0c0"]))
    e.create()  # the frame-less leftover of its own name is removed, and the name recorded
    assert empty.is_dir() and list(empty.iterdir()) == [] and e.plan.folder == empty
    e.discard()


@pytest.mark.parametrize("name", ["T1", "S01-02-T03", "a.b_c-d", "9" * 128])
def test_plain_names_pass(name: str) -> None:
    assert check_take_name(name) == name


@pytest.mark.parametrize(
    "name",
    # "T1\n" passed before (a ^...$ pattern by re.match: $ matches before a last newline), and made a folder
    # and an ALE whose name held it, which take check then failed and printed over lines
    ["T1\n", "\nT1", "T1\r", "T 1", "", ".T1", "-T1", "../T1", "a/b", "a" * 129, "T1\x00", "T\u00e91"],
)
def test_other_names_are_refused_in_one_line(name: str) -> None:
    with pytest.raises(ParameterError) as err:
        check_take_name(name)
    assert "\n" not in str(err.value).replace("\\n", "")
