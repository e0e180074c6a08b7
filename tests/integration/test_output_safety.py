"""Issue 25, through the installed ``rigctl``: names from data never leave the output folder, takes that lie
are refused, outputs that cannot be written say so in one line, and a second run on a folder is refused."""

from __future__ import annotations

import contextlib
import fcntl
import os
import stat
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from conftest import SHARED
from hostile_support import one_line  # type: ignore[import-not-found]
from reliab_support import (  # type: ignore[import-not-found]
    camera_file,
    copy_take,
    edit_manifest,
    in_mount,
    make_tiny,
    rewrite_records,
    rigctl,
)

from rigctl.errors import EXIT_BAD_INPUT, EXIT_CHECK_FAILED, EXIT_DAMAGED, EXIT_DEVICE, EXIT_USAGE
from rigctl.publish import TEMP_SUFFIX

VICTIM = "../../../../../../tmp/rigctl-victim-{}/victim"


@pytest.fixture(scope="module")
def tiny(module_tmp: Callable[[str], Path]) -> tuple[Path, Path]:
    return make_tiny(module_tmp("tiny"))


def nothing_in(folder: Path) -> bool:
    return not folder.exists() or not any(folder.iterdir())


# 1. one way to name files from data


def test_a_camera_name_that_climbs_out_is_refused_by_check_export_and_depth(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    victim = Path(f"/tmp/rigctl-victim-{os.getpid()}")
    name = VICTIM.format(os.getpid())
    take = copy_take(tiny[0], tmp_path / "t")
    edit_manifest(take, lambda m: m["cameras"].update({name: m["cameras"].pop("r0c0")}))
    res = rigctl("take", "check", str(take))
    assert res.returncode == EXIT_CHECK_FAILED and "is not a camera name" in res.stderr
    one_line(rigctl("take", "export", str(take), "--out", str(tmp_path / "x")), EXIT_BAD_INPUT, "cameras", name)
    rect = copy_take(tiny[1], tmp_path / "r")

    def rename(m: dict[str, Any]) -> None:
        m["cameras"][name] = m["cameras"].pop("r0c0")
        m["rectification"]["positions_m"][name] = m["rectification"]["positions_m"].pop("r0c0")

    edit_manifest(rect, rename)
    one_line(rigctl("depth", str(rect), "--out", str(tmp_path / "y"), "--preset", "fast"), EXIT_BAD_INPUT, name)
    edit_manifest(rect, lambda m: m["cameras"].update({"r0c0": m["cameras"].pop(name)}))
    res = rigctl("depth", str(rect), "--out", str(tmp_path / "y"), "--preset", "fast")
    one_line(res, EXIT_BAD_INPUT, "positions_m")
    assert not victim.exists()
    assert nothing_in(tmp_path / "x") and nothing_in(tmp_path / "y")


@pytest.mark.parametrize(
    ("case", "fragment"),
    [
        ("other_cameras_files", "is not camera r0c0's file"),
        ("no_cameras", "the take has no cameras"),
        ("bogus_status", "'bogus' is not a status"),
        ("newline_name", "is not a camera name"),
    ],
)
def test_manifest_lies_are_refused(tiny, tmp_path: Path, case: str, fragment: str) -> None:  # type: ignore[no-untyped-def]
    take = copy_take(tiny[0], tmp_path / "t")

    def edit(m: dict[str, Any]) -> None:
        if case == "other_cameras_files":
            m["cameras"]["r0c0"].update(essence=m["cameras"]["r0c1"]["essence"], index=m["cameras"]["r0c1"]["index"])
        elif case == "no_cameras":
            m["cameras"] = {}
        elif case == "bogus_status":
            m["status"] = "bogus"
        else:
            m["cameras"]["r0c0\n"] = m["cameras"].pop("r0c0")

    edit_manifest(take, edit)
    res = rigctl("take", "check", str(take))
    assert res.returncode == EXIT_CHECK_FAILED and fragment in res.stderr, res.stderr
    one_line(rigctl("take", "export", str(take), "--out", str(tmp_path / "x")), EXIT_BAD_INPUT, fragment)
    assert nothing_in(tmp_path / "x")


# 3. take check proves the take


@pytest.mark.parametrize(
    ("case", "fragment"),
    [
        ("all_offsets_zero", "lies inside or before the frame"),
        ("negated_times", "capture time goes backwards"),
        ("huge_capture_time", "span"),
        ("too_fast", "faster than the rate allows"),
        ("record_of_4gib", "runs past the end of the essence file"),
    ],
)
def test_index_records_that_lie_with_a_valid_crc_are_refused(tiny, tmp_path: Path, case: str, fragment: str) -> None:  # type: ignore[no-untyped-def]
    take = copy_take(tiny[0], tmp_path / "t")

    def edit(i: int, f: dict[str, Any]) -> None:
        if case == "all_offsets_zero":
            f["offset"] = 0
        elif case == "negated_times":
            f["capture_ns"] = -f["capture_ns"]
        elif case == "huge_capture_time" and i == 2:  # the last frame: times still increase
            f["capture_ns"] = 9 * 10**18
        elif case == "too_fast":
            f["capture_ns"] = 10**9 + i
        elif case == "record_of_4gib" and i == 0:
            f["size"] = 2**32 - 1

    rewrite_records(camera_file(take, "r0c0", "index"), edit)
    res = rigctl("take", "check", str(take), timeout=60)
    assert res.returncode == EXIT_CHECK_FAILED and fragment in res.stderr, res.stderr
    res = rigctl("take", "export", str(take), "--out", str(tmp_path / "x"), timeout=60)
    assert res.returncode in (EXIT_BAD_INPUT, EXIT_DAMAGED) and fragment in res.stderr, res.stderr
    one_line(res, res.returncode)
    assert nothing_in(tmp_path / "x")


@pytest.mark.parametrize("which", ["both", "index"])
def test_two_cameras_files_swapped_on_disk_are_refused(tiny, tmp_path: Path, which: str) -> None:  # type: ignore[no-untyped-def]
    """Every checksum holds when two cameras' files trade places; the index records name their camera."""
    for src, name in ((tiny[0], "t"), (tiny[1], "r")):
        take = copy_take(src, tmp_path / name)
        for kind in ("essence", "index") if which == "both" else ("index",):
            a, b = camera_file(take, "r0c0", kind), camera_file(take, "r0c1", kind)
            a.rename(a.with_name("swap")), b.rename(a), a.with_name("swap").rename(b)
        res = rigctl("take", "check", str(take), timeout=60)
        assert res.returncode == EXIT_CHECK_FAILED, res.stderr
        assert "record of camera r0c1's frame in camera r0c0's index" in res.stderr and "swapped" in res.stderr
        out = tmp_path / f"x-{name}"
        one_line(rigctl("take", "export", str(take), "--out", str(out), timeout=60), EXIT_BAD_INPUT, "swapped")
        assert nothing_in(out)
    res = rigctl("depth", str(tmp_path / "r"), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=60)
    one_line(res, EXIT_BAD_INPUT, "r0c0", "swapped")
    assert nothing_in(tmp_path / "d")


def test_a_take_whose_records_name_no_camera_still_reads_with_a_notice(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """An older take (index version 1: no camera in its records) reads as before; readers say once that a swap
    of its files cannot be detected."""
    take = copy_take(tiny[0], tmp_path / "t")
    for cam in ("r0c0", "r1c1"):

        def old(i: int, f: dict[str, Any]) -> None:
            f["version"], f["res"] = 1, 0

        rewrite_records(camera_file(take, cam, "index"), old)
    res = rigctl("take", "check", str(take), timeout=60)
    assert res.returncode == 0, res.stderr
    assert "r0c0, r1c1 name no camera" in res.stdout + res.stderr and "cannot be detected" in res.stdout + res.stderr
    res = rigctl("take", "export", str(take), "--out", str(tmp_path / "x"), timeout=60)
    assert res.returncode == 0 and res.stderr.count("cannot be detected") == 1, res.stderr
    reference = rigctl("take", "export", str(tiny[0]), "--out", str(tmp_path / "y"), timeout=60)
    assert reference.returncode == 0, reference.stderr
    mine = sorted(p.relative_to(tmp_path / "x") for p in (tmp_path / "x").rglob("*.png"))
    assert mine and mine == sorted(p.relative_to(tmp_path / "y") for p in (tmp_path / "y").rglob("*.png"))
    assert all((tmp_path / "x" / p).read_bytes() == (tmp_path / "y" / p).read_bytes() for p in mine)
    # one camera's records mixing both versions is no older take: refused
    rewrite_records(camera_file(take, "r0c0", "index"), lambda i, f: f.update(version=2, res=0) if i == 0 else None)
    res = rigctl("take", "check", str(take), timeout=60)
    assert res.returncode == EXIT_CHECK_FAILED and "a version 1 record" in res.stderr, res.stderr


@pytest.mark.parametrize(
    ("case", "fragment"),
    [
        ("swapped_size", "differs from the rig snapshot"),
        ("period_of_1ns", "frame_period_ns 1 does not agree"),
        ("huge_format", "format"),
    ],
)
def test_format_and_timing_lies_are_refused(tiny, tmp_path: Path, case: str, fragment: str) -> None:  # type: ignore[no-untyped-def]
    take = copy_take(tiny[0], tmp_path / "t")

    def edit(m: dict[str, Any]) -> None:
        f = m["format"]
        if case == "swapped_size":
            f["width"], f["height"] = f["height"], f["width"]
        elif case == "period_of_1ns":
            m["timing"]["frame_period_ns"] = 1
        else:
            f["width"] = f["height"] = 46000
            f["bytes_per_frame"] = 46000 * 46000 * 2

    edit_manifest(take, edit)
    res = rigctl("take", "check", str(take), timeout=60)
    assert res.returncode == EXIT_CHECK_FAILED and fragment in res.stderr, res.stderr
    one_line(rigctl("take", "export", str(take), "--out", str(tmp_path / "x"), timeout=60), EXIT_BAD_INPUT, fragment)


# 4. regular files only, bounded


@pytest.mark.parametrize("what", ["manifest_dev_zero", "manifest_fifo", "index_fifo", "index_sparse", "essence_dir"])
def test_files_that_are_not_regular_or_absurdly_large_are_refused(tiny, tmp_path: Path, what: str) -> None:  # type: ignore[no-untyped-def]
    take = copy_take(tiny[0], tmp_path / "t")
    if what == "manifest_dev_zero":
        (take / "take.yaml").unlink()
        (take / "take.yaml").symlink_to("/dev/zero")
        fragment = "not a regular file"
    elif what == "manifest_fifo":
        (take / "take.yaml").unlink()
        os.mkfifo(take / "take.yaml")
        fragment = "not a regular file"
    elif what == "index_fifo":
        index = camera_file(take, "r0c0", "index")
        index.unlink()
        os.mkfifo(index)
        fragment = "not a regular file"
    elif what == "index_sparse":
        with open(camera_file(take, "r0c0", "index"), "r+b") as f:
            f.truncate(6 << 30)
        fragment = "holds more records than its essence file can hold"
    else:
        essence = camera_file(take, "r0c0", "essence")
        essence.unlink()
        essence.mkdir()
        fragment = "is a folder"
    for argv in (("take", "info", str(take)), ("take", "export", str(take), "--out", str(tmp_path / "x"))):
        res = rigctl(*argv, timeout=30)
        assert res.returncode in (EXIT_BAD_INPUT, EXIT_DAMAGED), res.stderr
        one_line(res, res.returncode, fragment)
    rig = tmp_path / "rig.yaml"
    rig.symlink_to("/dev/zero")
    one_line(rigctl("plan", str(rig), timeout=30), EXIT_BAD_INPUT, "not a regular file")


# 5. one line for every failure of the output side


def test_a_path_that_is_not_utf8_is_refused_before_any_work(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    bad = os.fsdecode(os.fsencode(str(tmp_path)) + b"/out\xff")
    for argv in (
        ("take", "export", str(tiny[0]), "--out", bad),
        ("depth", str(tiny[1]), "--out", bad, "--preset", "fast"),
        ("rectify", str(tiny[0]), "--calibration", str(tiny[0] / "truth/calibration.yaml"), "--out", bad),
    ):
        one_line(rigctl(*argv), EXIT_USAGE, "not valid UTF-8")
    assert not os.path.exists(os.fsencode(bad))


def test_out_naming_a_file_is_one_line(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "f").write_text("mine")
    one_line(rigctl("take", "export", str(tiny[0]), "--out", str(tmp_path / "f")), EXIT_DEVICE, "is a file")
    one_line(rigctl("depth", str(tiny[1]), "--out", str(tmp_path / "f")), EXIT_DEVICE, "is a file")
    assert (tmp_path / "f").read_text() == "mine"


def test_read_only_and_full_destinations_are_one_line(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    mnt = tmp_path / "mnt"
    cal = str(tiny[0] / "truth/calibration.yaml")
    cases = [
        ("ro", ("take", "export", str(tiny[0]), "--out", str(mnt / "x")), "read-only"),
        ("ro", ("depth", str(tiny[1]), "--out", str(mnt), "--preset", "fast"), "read-only"),
        ("ro", ("rectify", str(tiny[0]), "--calibration", cal, "--out", str(mnt / "r")), "read-only"),
        ("ro", ("process", str(tiny[1]), "--out", str(mnt / "p"), "--workers", "1"), "read-only"),
        ("ro", ("demo", "--out", str(mnt / "d")), "read-only"),
        # a destination too small for what the run will write is refused up front, before a file is made
        ("size=48k", ("take", "export", str(tiny[0]), "--out", str(mnt / "x")), "MB free on its file system"),
        ("size=48k", ("depth", str(tiny[1]), "--out", str(mnt), "--preset", "fast"), "MB free on its file system"),
        ("size=48k", ("rectify", str(tiny[0]), "--calibration", cal, "--out", str(mnt / "r")), "MB free on its"),
        ("size=48k", ("demo", "--out", str(mnt / "d")), "needed for the demo's takes"),
    ]
    for options, argv, fragment in cases:
        res = in_mount(mnt, options, *argv)
        if res is None:
            pytest.skip("mounting a tmpfs needs root or user namespaces")
        one_line(res, EXIT_DEVICE, str(mnt), fragment)


def test_a_second_run_on_a_locked_folder_is_refused(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "x"
    out.mkdir()
    fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a running rigctl holds it
        one_line(rigctl("take", "export", str(tiny[0]), "--out", str(out)), EXIT_DEVICE, "another rigctl run")
        one_line(rigctl("depth", str(tiny[1]), "--out", str(out), "--preset", "fast"), EXIT_DEVICE, "another rigctl")
        # two process runs on one --out each wrote back their own ledger: the second is refused
        one_line(rigctl("process", str(tiny[1]), "--out", str(out), "--workers", "1"), EXIT_DEVICE, "another rigctl")
    finally:
        os.close(fd)
    assert nothing_in(out)
    assert rigctl("take", "export", str(tiny[0]), "--out", str(out)).returncode == 0


def test_a_link_planted_in_the_output_folder_is_not_followed_out_of_it(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """A frame folder that is a symbolic link to elsewhere (left by someone, or by a hostile user) would have
    a run write its files outside --out: refused in one line, the place it points at untouched."""
    victim = tmp_path / "victim"
    victim.mkdir()
    runs = {
        "export": ("take", "export", str(tiny[0]), "--out"),
        "depth": ("depth", str(tiny[1]), "--preset", "fast", "--out"),
        "render": ("render", str(tiny[1]), "--disparity", str(tiny[1] / "truth" / "disparity"), "--at", "1,1", "--out"),
        "process": ("process", str(tiny[1]), "--workers", "1", "--preset", "fast", "--out"),
    }
    for verb, argv in runs.items():
        out = tmp_path / verb
        frames = out / "depth" if verb == "process" else out
        frames.mkdir(parents=True)
        (frames / "000001").symlink_to(victim)
        res = rigctl(*argv, str(out), timeout=120)
        if verb == "process":  # the farm records the frame as failed and goes on with the others (exit 1)
            assert res.returncode == EXIT_CHECK_FAILED and "000001: is a symbolic link inside" in res.stderr
        else:
            one_line(res, EXIT_DEVICE, "000001", "symbolic link inside the output folder")
        assert not any(victim.iterdir()), verb


def test_a_demo_on_a_folder_another_demo_is_writing_is_refused_and_clears_nothing(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    (out / "takes").mkdir(parents=True)
    (out / ".rigctl-demo").write_text("an unfinished demo: a second demo would replace it\n")
    fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as the running demo holds it
        one_line(rigctl("demo", "--out", str(out), timeout=60), EXIT_DEVICE, str(out), "another rigctl run")
    finally:
        os.close(fd)
    assert (out / "takes").is_dir() and (out / ".rigctl-demo").exists()


def test_demo_fresh_never_clears_a_folder_that_holds_no_demo(tmp_path: Path) -> None:
    """``--fresh`` replaces a finished demo; somebody's folder is refused in one line and kept as it was."""
    mine = tmp_path / "mine"
    (mine / "sub").mkdir(parents=True)
    (mine / "notes.txt").write_text("keep")
    (mine / "sub" / "d.bin").write_bytes(b"x")
    one_line(rigctl("demo", "--out", str(mine), "--fresh", timeout=60), EXIT_USAGE, str(mine), "holds no demo")
    assert (mine / "notes.txt").read_text() == "keep" and (mine / "sub" / "d.bin").read_bytes() == b"x"
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt", "sub"]


def test_an_output_name_held_by_a_fifo_or_a_device_is_not_replaced(tmp_path: Path) -> None:
    """Outputs are published by rename over their final name: a FIFO (or a device, or a folder) found there is
    refused in one line, not replaced by a regular file."""
    os.mkfifo(tmp_path / "b.yaml")
    (tmp_path / "c.yaml").mkdir()
    for stem in ("b", "c"):
        run = rigctl("board", "--out", str(tmp_path / stem), timeout=60)
        one_line(run, EXIT_DEVICE, f"{stem}.yaml", "not replaced")
    assert stat.S_ISFIFO(os.lstat(tmp_path / "b.yaml").st_mode) and (tmp_path / "c.yaml").is_dir()
    assert not any(p.name.endswith(TEMP_SUFFIX) for p in tmp_path.iterdir())  # no temporary left behind


def test_board_never_replaces_an_existing_board(tmp_path: Path) -> None:
    """A second ``board`` on the same --out would leave a printed board measured by another description (and
    calibration using the wrong square size): refused in one line naming the file, as usd and miv refuse."""
    first = rigctl("board", "--out", str(tmp_path / "b"), "--squares", "5x4", "--square-mm", "30",
                   "--marker-mm", "22", "--dpi", "300", timeout=60)  # fmt: skip
    assert first.returncode == 0, first.stderr
    png, yml = (tmp_path / "b.png").read_bytes(), (tmp_path / "b.yaml").read_bytes()
    one_line(rigctl("board", "--out", str(tmp_path / "b"), timeout=60), EXIT_USAGE, "b.png", "already exists")
    assert (tmp_path / "b.png").read_bytes() == png and (tmp_path / "b.yaml").read_bytes() == yml
    (tmp_path / "c.yaml").write_text("mine")  # either file alone is enough to refuse, and nothing is written
    one_line(rigctl("board", "--out", str(tmp_path / "c"), timeout=60), EXIT_USAGE, "c.yaml", "already exists")
    assert (tmp_path / "c.yaml").read_text() == "mine" and not (tmp_path / "c.png").exists()


@pytest.mark.parametrize("raced", ["b.png", "b.yaml"])
def test_board_published_by_another_run_meanwhile_is_not_replaced(
    tmp_path: Path, raced: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two ``board`` runs on one --out at the same instant both pass the check for an existing board; the one
    that publishes second must not replace the first's files. The other run is simulated by writing its
    file while this one draws (after the check, before the publish)."""
    import rigctl.board
    from rigctl.cli.main import main

    drawn = rigctl.board.BoardSpec.image

    def draw_while_another_run_publishes(self: Any, *args: Any) -> Any:
        (tmp_path / raced).write_bytes(b"the other run's")
        return drawn(self, *args)

    monkeypatch.setattr(rigctl.board.BoardSpec, "image", draw_while_another_run_publishes)
    code = main(["board", "--out", str(tmp_path / "b"), "--squares", "5x4", "--square-mm", "30",
                 "--marker-mm", "22", "--dpi", "100"])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_USAGE and len(err) == 1 and raced in err[0] and "already exists" in err[0], err
    assert (tmp_path / raced).read_bytes() == b"the other run's"
    assert sorted(p.name for p in tmp_path.iterdir()) == [raced]  # nothing of ours, no temporary


# 4. numbers bounded to physical ranges; the machine bounds the workers


@pytest.mark.parametrize(
    ("key", "value", "fragment"),
    [
        ("fps", 1e-9, "format.fps must be >= 1"),
        ("width_px", 46000, "over the budget of 134,217,728 pixels"),
        ("spacing_x_m", 120000.0, "grid.spacing_x_m"),
    ],
)
def test_rig_numbers_beyond_physical_ranges_are_refused(tmp_path: Path, key: str, value: float, fragment: str) -> None:
    from hostile_support import SIM_RIG, write_yaml  # type: ignore[import-not-found]

    rig = {**SIM_RIG, "format": dict(SIM_RIG["format"]), "grid": dict(SIM_RIG["grid"])}
    if key == "spacing_x_m":
        rig["grid"][key] = value
    else:
        rig["format"][key] = value
        if key == "width_px":
            rig["format"]["height_px"] = value
    path = write_yaml(tmp_path / "rig.yaml", rig)
    one_line(rigctl("plan", str(path)), EXIT_BAD_INPUT, str(path), fragment)


@pytest.mark.parametrize(
    ("flag", "value", "fragment"),
    [
        ("--workers", "1000", "local workers on this machine"),
        ("--workers", "0", "1 to"),
        ("--memory-limit", "-1", "expected auto or a size"),
        ("--memory-limit", "1PiB", "expected auto or a size"),
        ("--memory-limit", "1000TB", "this machine's memory"),
    ],
)
def test_process_workers_and_memory_are_bounded_by_the_machine(
    tiny, tmp_path: Path, flag: str, value: str, fragment: str
) -> None:  # type: ignore[no-untyped-def]
    res = rigctl("process", str(tiny[1]), "--out", str(tmp_path / "p"), flag, value)
    one_line(res, EXIT_USAGE, flag, fragment)
    assert not (tmp_path / "p").exists()


def grid_folder(folder: Path) -> Path:
    import cv2
    import numpy as np

    folder.mkdir()
    rng = np.random.default_rng(1)
    left = rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)
    cv2.imwrite(str(folder / "r0c0.png"), left)
    cv2.imwrite(str(folder / "r0c1.png"), np.roll(left, -3, axis=1))
    (folder / "grid.yaml").write_text("spacing_x: 1\nspacing_y: 1\nfocal_px: 100\n")
    return folder


def png_header(width: int, height: int) -> bytes:
    import struct
    import zlib

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))


@pytest.mark.parametrize(
    ("case", "fragment"),
    [
        ("32000x32000", "outside what rigctl decodes"),
        ("100000x1", "outside what rigctl decodes"),
        ("4000x60", "more than 64:1"),
        ("not_png", "not a PNG image"),
        ("fifo", "not a regular file"),
        ("bad_range", "disparity_range_px: expected [min, max]"),
        ("reversed_range", "disparity_range_px"),
        ("absurd_focal", "focal_px: 1e+300 is not plausible for pictures 64 px wide"),
    ],
)
def test_grid_folder_pictures_are_checked_before_decoding(tmp_path: Path, case: str, fragment: str) -> None:
    grid = grid_folder(tmp_path / "g")
    if case == "not_png":
        (grid / "r0c1.png").write_bytes(b"GIF89a" + bytes(100))
    elif case == "fifo":
        (grid / "r0c1.png").unlink()
        os.mkfifo(grid / "r0c1.png")
    elif case == "bad_range":
        (grid / "grid.yaml").write_text("spacing_x: 1\nfocal_px: 100\ndisparity_range_px: [0, .nan]\n")
    elif case == "reversed_range":
        (grid / "grid.yaml").write_text("spacing_x: 1\nfocal_px: 100\ndisparity_range_px: [9, 2]\n")
    elif case == "absurd_focal":
        (grid / "grid.yaml").write_text("spacing_x: 1\nfocal_px: 1.0e+300\n")
    else:
        w, h = (int(v) for v in case.split("x"))
        (grid / "r0c1.png").write_bytes(png_header(w, h) + bytes(1 << 20))
    one_line(rigctl("depth", str(grid), "--out", str(tmp_path / "d"), timeout=60), EXIT_BAD_INPUT, fragment)


def test_a_stray_png_beside_the_grid_is_left_out_not_misreported(tmp_path: Path) -> None:
    grid = grid_folder(tmp_path / "g")
    (grid / "rXcY.png").write_bytes((grid / "r0c0.png").read_bytes())
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=120)
    assert res.returncode == 0, res.stderr
    assert "rXcY.png: not named r{row}c{col}.png" in res.stderr
    assert sorted(p.name for p in (tmp_path / "d").glob("*.exr")) == ["r0c0.exr", "r0c1.exr"]


@pytest.mark.parametrize("kind", ["a FIFO", "a device", "a folder", "a symlink loop", "a dangling symlink"])
def test_a_truth_pfm_that_is_there_but_no_regular_file_is_refused_not_skipped(tmp_path: Path, kind: str) -> None:
    """truth/<camera>.pfm as a FIFO, a device, a folder or a symlink loop was skipped as if absent (depth ran
    unscored, exit 0); a FIFO must be refused without being waited on (the timeout would end the run)."""
    grid = grid_folder(tmp_path / "g")
    pfm = grid / "truth" / "r0c0.pfm"
    pfm.parent.mkdir()
    if kind == "a FIFO":
        os.mkfifo(pfm)
    elif kind == "a device":
        pfm.symlink_to("/dev/null")
    elif kind == "a folder":
        pfm.mkdir()
    elif kind == "a symlink loop":
        pfm.symlink_to(pfm.name)
    else:
        pfm.symlink_to(tmp_path / "nowhere.pfm")
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=60)
    one_line(res, EXIT_BAD_INPUT, f"{pfm}: ")
    assert not (tmp_path / "d" / "r0c0.exr").exists()


def test_a_truth_that_is_no_folder_is_refused(tmp_path: Path) -> None:
    grid = grid_folder(tmp_path / "g")
    os.mkfifo(grid / "truth")
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=60)
    one_line(res, EXIT_BAD_INPUT, f"{grid / 'truth'}: reference disparities: expected a folder")


@pytest.mark.parametrize("names", [("r01c0", "r1c0"), ("r0c00", "r0c0"), ("r01c0",)])
def test_a_grid_position_with_a_leading_zero_is_refused_naming_the_files(
    tmp_path: Path, names: tuple[str, ...]
) -> None:
    """r01c0.png beside r1c0.png read as two cameras at one grid position (exit 0, two depth maps of one place);
    positions are written without leading zeros, so one alone is refused too, naming the name to use."""
    grid = grid_folder(tmp_path / "g")
    for n in names:
        (grid / f"{n}.png").write_bytes((grid / "r0c1.png").read_bytes())
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=60)
    camera = names[-1] if len(names) > 1 else "r1c0"
    said = one_line(res, EXIT_BAD_INPUT, *(f"{grid / n}.png" for n in names), f"{camera}.png")
    assert ("2 pictures of camera" if len(names) > 1 else "leading zero") in said
    assert not (tmp_path / "d").exists() or nothing_in(tmp_path / "d")


@pytest.mark.parametrize(("name", "right"), [("r0c١", "r0c1"), ("r0c１", "r0c1"), ("r0c001", "r0c1")])
def test_a_grid_position_in_other_digits_is_refused_naming_the_name_to_use(
    tmp_path: Path, name: str, right: str
) -> None:
    """r0c١.png (an Arabic-Indic one) was no grid position to the grid folder's [0-9]: it was left out with a
    warning and the grid read without it (here r0c0 alone: 'no depth could be estimated'), where a rig file and
    a calibration took the same name as camera r0c1."""
    grid = grid_folder(tmp_path / "g")
    (grid / "r0c1.png").rename(grid / f"{name}.png")
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=60)
    one_line(res, EXIT_BAD_INPUT, f"{grid / name}.png: grid position is written with", f"name it {right}.png")
    assert nothing_in(tmp_path / "d")


def test_a_camera_that_shares_no_view_with_the_grid_is_refused_a_gap_is_not(tmp_path: Path) -> None:
    """r9999c9999.png beside the grid was left out of every other camera's views and estimated alone from
    disparities under 0.01 px, exit 0. A camera a few steps off (a gap in the grid) still shares a view."""
    grid = grid_folder(tmp_path / "g")
    (grid / "r9999c9999.png").write_bytes((grid / "r0c1.png").read_bytes())
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d"), "--preset", "fast", timeout=60)
    one_line(res, EXIT_BAD_INPUT, f"{grid / 'r9999c9999.png'}: shares no view with any other camera", "r0c1.png")
    assert nothing_in(tmp_path / "d")
    (grid / "r9999c9999.png").rename(grid / "r1c7.png")
    res = rigctl("depth", str(grid), "--out", str(tmp_path / "d2"), "--preset", "fast", timeout=120)
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "d2").glob("*.exr")) == ["r0c0.exr", "r0c1.exr", "r1c7.exr"]


def test_bench_depth_size_is_checked_against_the_memory_it_needs() -> None:
    from rigctl.cli.bench import check_depth_bench_memory
    from rigctl.errors import ParameterError

    check_depth_bench_memory((960, 540), 9, 8 << 30)
    check_depth_bench_memory((16384, 16384), 9, None)  # no figure, no check
    with pytest.raises(ParameterError, match=r"needs about 102\.4 GB, 8\.0 GB available"):
        check_depth_bench_memory((16384, 16384), 9, 8 << 30)
    one_line(rigctl("bench", "depth", "--size", "16384x16384"), EXIT_USAGE, "--size 16384x16384", "GB available")


@pytest.mark.parametrize("peer", ["silent", "garbage", "closes"])
def test_a_scheduler_address_that_is_no_dask_scheduler_is_one_line(tiny, tmp_path: Path, peer: str) -> None:  # type: ignore[no-untyped-def]
    import socket
    import threading

    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]

    def serve() -> None:
        conn, _ = server.accept()
        with conn, contextlib.suppress(OSError):  # the client hangs up as soon as it has read enough
            if peer == "garbage":
                conn.sendall(b"\xff" * 64)
                conn.recv(1)

    if peer != "silent":  # silent: the kernel accepts into the backlog and nobody ever speaks
        threading.Thread(target=serve, daemon=True).start()
    try:
        res = rigctl("process", str(tiny[1]), "--out", str(tmp_path / "p"), "--scheduler", f"tcp://127.0.0.1:{port}")
    finally:
        server.close()
    one_line(res, EXIT_DEVICE, "--scheduler", "not a Dask scheduler")


def test_a_scheduler_host_the_resolver_refuses_is_one_line(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """``a..b`` passes the address's form but not the resolver's IDNA encoding, which raised a UnicodeError."""
    res = rigctl("process", str(tiny[1]), "--out", str(tmp_path / "p"), "--scheduler", "tcp://a..b:8786")
    one_line(res, EXIT_DEVICE, "--scheduler", "'a..b' is not a host name")


@pytest.mark.parametrize("mode", ["length", "buffers"])
def test_a_scheduler_that_shakes_hands_then_claims_a_huge_message_is_one_line(tiny, tmp_path: Path, mode: str) -> None:  # type: ignore[no-untyped-def]
    """Past the handshake (which the probe checks), every message is bounded too: a peer that speaks Dask's
    handshake, then claims exabytes (or a small header listing terabyte buffers), is refused in one line,
    within a 2.5 GB address space, instead of a traceback from numpy asked for 4 EiB."""
    import resource
    import subprocess
    import sys

    from tests_support import rigctl_exe  # type: ignore[import-not-found]

    server = subprocess.Popen(
        [sys.executable, str(Path(__file__).resolve().parents[1] / "hostile_scheduler.py"), mode],
        stdout=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        assert server.stdout is not None
        address = server.stdout.readline().strip()
        assert address.startswith("tcp://"), address

        def limit() -> None:
            resource.setrlimit(resource.RLIMIT_AS, (5 << 29, 5 << 29))

        res = subprocess.run(
            [*rigctl_exe(), "process", str(tiny[1]), "--out", str(tmp_path / "p"), "--scheduler", address],
            capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL, preexec_fn=limit,
        )  # fmt: skip
    finally:
        server.kill()
        server.wait()
    one_line(res, EXIT_DEVICE, "--scheduler", "sent a message of", "refused")


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (("--square-mm", "1000", "--marker-mm", "900", "--dpi", "2400", "--squares", "22x22"), "pixels: lower"),
        (("--square-mm", "inf", "--marker-mm", "5"), "--square-mm inf"),
        (("--margin-mm", "1e12"), "pixels: lower"),
        # more markers than the dictionary has, and a square of no size (the marker was blamed)
        (("--squares", "23x23", "--square-mm", "20", "--marker-mm", "15"), "needs 264 markers"),
        (("--square-mm", "0"), "--square-mm 0: must be a positive length"),
    ],
)
def test_board_sizes_that_need_terabytes_are_one_line(tmp_path: Path, argv: tuple[str, ...], fragment: str) -> None:
    one_line(rigctl("board", "--out", str(tmp_path / "b"), *argv), EXIT_USAGE, fragment)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (("--marker-mm", "1e-300"), "--marker-mm 1e-300 must be at least 0.1 mm and smaller than --square-mm 75"),
        (("--marker-mm", "0.85"), "--marker-mm 0.85 at 150 dpi is 5 px: a DICT_5X5_250 marker needs at least 7 px"),
    ],
)
def test_a_board_marker_too_small_to_draw_is_one_line(tmp_path: Path, argv: tuple[str, ...], fragment: str) -> None:
    """A marker of 1e-300 mm ended in a SystemError traceback from cv2.aruco.CharucoBoard, one of 0.85 mm (5 px,
    fewer than its 5x5 bits and border) in OpenCV's assertion text."""
    one_line(rigctl("board", "--out", str(tmp_path / "b"), *argv), EXIT_USAGE, fragment)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("square", ["1e300", "1e-300", "nan", "0"])
def test_a_chessboard_square_out_of_sense_is_one_line_naming_square(tmp_path: Path, square: str) -> None:
    """--square 1e300 ended in OpenCV's assertion text and 1e-300 in 'points all at one place'; the same square in
    a chessboard board file too. Refused before any work, stating the bounds."""
    source = str(SHARED / "data" / "opencv-stereo-chessboard")
    run = rigctl("calibrate", source, "--chessboard", "9x6", "--square", square, "--out", str(tmp_path / "c.yaml"))
    said = one_line(run, EXIT_USAGE, "--square ", "must be 0.0001 to 1000")
    assert "Assertion" not in said and "one place" not in said
    board = tmp_path / "board.yaml"
    board.write_text(f"type: chessboard\ncolumns: 9\nrows: 6\nsquare: {float(square)!r}\n".replace("nan", ".nan"))
    run = rigctl("calibrate", source, "--board", str(board), "--out", str(tmp_path / "c.yaml"))
    one_line(run, EXIT_BAD_INPUT, f"{board}: square: must be 0.0001 to 1000")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["board.yaml"]


def test_a_fifo_among_the_calibration_pictures_is_refused_not_waited_on(tmp_path: Path) -> None:
    pictures = tmp_path / "cb"
    pictures.mkdir()
    source = SHARED / "data" / "opencv-stereo-chessboard"
    for name in ("left01.jpg", "left02.jpg", "right01.jpg", "right02.jpg"):
        (pictures / name).write_bytes((source / name).read_bytes())
    os.mkfifo(pictures / "right03.jpg")  # a FIFO nobody writes: cv2.imread waited on it for ever
    run = rigctl("calibrate", str(pictures), "--chessboard", "9x6", "--out", str(tmp_path / "c.yaml"), timeout=120)
    one_line(run, EXIT_BAD_INPUT, "right03.jpg", "not a regular file")
    assert not (tmp_path / "c.yaml").exists()


def test_the_shoot_ui_without_a_terminal_is_one_line_not_a_screen_drawn_for_ever(tmp_path: Path) -> None:
    run = rigctl("tui", "--out", str(tmp_path / "takes"), timeout=60)  # input /dev/null, output a pipe
    one_line(run, EXIT_USAGE, "needs a terminal")
    assert not (tmp_path / "takes").exists()


def test_a_run_that_fails_before_writing_leaves_no_folder_it_made_and_keeps_one_it_found(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    one_line(rigctl("depth", str(tmp_path / "nothing"), "--out", str(tmp_path / "d")), EXIT_USAGE, "not a take")
    one_line(rigctl("take", "export", str(tiny[0]), "--out", str(tmp_path / "x"), "--frames", "5"), EXIT_USAGE, "5")
    assert not (tmp_path / "d").exists() and not (tmp_path / "x").exists()  # made by the run, removed again
    (tmp_path / "mine").mkdir()
    one_line(rigctl("depth", str(tmp_path / "nothing"), "--out", str(tmp_path / "mine")), EXIT_USAGE, "not a take")
    assert (tmp_path / "mine").is_dir()  # the user's own (empty) folder stays


def test_an_empty_board_stem_and_an_endless_recording_are_one_line(tmp_path: Path) -> None:
    one_line(rigctl("board", "--out", "", cwd=tmp_path), EXIT_USAGE, "give a file stem")
    one_line(rigctl("record", "--take", "X", "--seconds", "inf", cwd=tmp_path), EXIT_USAGE, "--seconds must be")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(("options", "fragment"), [("ro", "b.png: the file system is read-only"),
                                                    ("size=16k", "no space left on the device")])  # fmt: skip
def test_board_on_a_read_only_or_full_disk_is_a_destination_error(tmp_path: Path, options: str, fragment: str) -> None:
    """Exit 4 like every other writer (it was 2, a usage error, and named the temporary file on a read-only one)."""
    res = in_mount(tmp_path / "mnt", options, "board", "--out", str(tmp_path / "mnt" / "b"))
    if res is None:
        pytest.skip("mounting a tmpfs needs root or user namespaces")
    assert TEMP_SUFFIX not in one_line(res, EXIT_DEVICE, fragment)


def test_render_into_a_device_or_a_file_is_a_destination_error(tmp_path: Path) -> None:
    """An --out that exists and is no folder is refused (exit 4, as publish refuses a device elsewhere) before
    the input is read."""
    (tmp_path / "afile").write_text("mine")
    for out, what in (("/dev/null", "it is a device"), (str(tmp_path / "afile"), "it is a file")):
        res = rigctl("render", str(tmp_path / "none"), "--disparity", str(tmp_path), "--at", "1,1", "--out", out)
        one_line(res, EXIT_DEVICE, f"--out {out}: cannot make the output folder: {what}")
    assert (tmp_path / "afile").read_text() == "mine"


def test_calibrate_refuses_its_outputs_before_reading_the_input(tmp_path: Path) -> None:
    """Corner detection and the solve take minutes: an --out (or --opencv, --colmap) that cannot be written is
    refused first, so even a missing input is not reached (the old code failed on the input, or after the solve)."""
    (tmp_path / "afile").write_text("mine")
    missing = str(tmp_path / "no-take")
    for argv, fragment in (
        (["--out", str(tmp_path)], f"--out {tmp_path}: is a folder, not a file"),
        (["--out", "/dev/null"], "--out /dev/null: is a device, not a file"),
        (["--out", str(tmp_path / "afile" / "c.yaml")], "afile is a file, not a folder"),
        (["--out", str(tmp_path / "c.yaml"), "--opencv", str(tmp_path)], "--opencv"),
        (["--out", str(tmp_path / "c.yaml"), "--colmap", str(tmp_path / "afile")], "--colmap"),
    ):
        one_line(rigctl("calibrate", missing, *argv), EXIT_DEVICE, fragment)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


@pytest.mark.parametrize("how", ["picture", "spelt another way", "symlink", "hard link", "board", "opencv"])
def test_calibrate_refuses_an_output_that_is_one_of_its_inputs(tmp_path: Path, how: str) -> None:
    """calibrate --out (or --opencv) named onto an input picture or the --board file was accepted and would
    replace it after the solve; refused before any work (exit 2), through symlinks and hard links."""
    pictures = tmp_path / "cb"
    pictures.mkdir()
    source = SHARED / "data" / "opencv-stereo-chessboard"
    for name in ("left01.jpg", "left02.jpg", "right01.jpg", "right02.jpg"):
        (pictures / name).write_bytes((source / name).read_bytes())
    board = tmp_path / "board.yaml"
    board.write_text("type: chessboard\ncolumns: 9\nrows: 6\nsquare: 0.025\n")
    target, victim = ["--chessboard", "9x6"], pictures / "left01.jpg"
    out = tmp_path / "c.yaml"
    extra: list[str] = []
    if how == "picture":
        out = victim
    elif how == "spelt another way":
        out = pictures / ".." / "cb" / "left01.jpg"
    elif how == "symlink":
        out = tmp_path / "link.yaml"
        out.symlink_to(victim)
    elif how == "hard link":
        out = tmp_path / "hard.yaml"
        os.link(victim, out)
    elif how == "board":
        target, victim, out = ["--board", str(board)], board, board
    else:
        extra = ["--opencv", str(pictures / "right02.jpg")]
        victim = pictures / "right02.jpg"
    before = victim.read_bytes()
    run = rigctl("calibrate", str(pictures), *target, "--out", str(out), *extra, timeout=60)
    said = one_line(run, EXIT_USAGE, "calibrate would write over what it reads", str(victim.name))
    assert ("the --board file" if how == "board" else f"an input file of {pictures}") in said
    assert victim.read_bytes() == before


@pytest.mark.parametrize(("errno_", "code", "fragment"), [(30, EXIT_DEVICE, "read-only"), (28, 4, "no space left")])
def test_an_os_error_no_verb_caught_is_still_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], errno_: int, code: int, fragment: str
) -> None:
    import rigctl.cli.plan
    from rigctl.cli.main import main

    def fails(ns: object) -> int:
        raise OSError(errno_, os.strerror(errno_), "/somewhere/file.png")

    monkeypatch.setattr(rigctl.cli.plan, "run", fails)
    assert main(["plan"]) == code
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "/somewhere/file.png" in err and fragment in err, err


def test_demo_and_record_refuse_an_unusable_out_before_any_work(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("mine")
    one_line(rigctl("demo", "--out", str(tmp_path / "f")), EXIT_DEVICE, "is a file, not a folder")
    assert (tmp_path / "f").read_text() == "mine"
    bad = os.fsdecode(os.fsencode(str(tmp_path)) + b"/takes\xff")
    one_line(rigctl("record", "--take", "t", "--frames", "2", "--out", bad, "--force"), EXIT_USAGE, "not valid UTF-8")
    assert not os.path.exists(os.fsencode(bad))


def test_a_calibration_whose_cameras_are_kilometres_apart_is_refused(tiny, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import yaml

    cal = yaml.safe_load((tiny[0] / "truth/calibration.yaml").read_text())
    cal["cameras"]["r2c2"]["t"][0] += 120_000.0
    path = tmp_path / "far.yaml"
    path.write_text(yaml.safe_dump(cal))
    res = rigctl("rectify", str(tiny[0]), "--calibration", str(path), "--out", str(tmp_path / "r"))
    one_line(res, EXIT_BAD_INPUT, "cameras.r2c2 lies", "within 1000 m")
    assert not (tmp_path / "r").exists()


def test_a_comparison_with_the_truth_never_stops_a_render(tmp_path: Path) -> None:
    """A simulated take with motion has no single truth view: render once wrote a view, then failed."""
    from hostile_support import SIM_RIG, write_yaml  # type: ignore[import-not-found]

    rig = dict(SIM_RIG, format={**SIM_RIG["format"], "width_px": 96, "height_px": 54})
    write_yaml(tmp_path / "rig.yaml", rig)
    res = rigctl(
        "record", str(tmp_path / "rig.yaml"), "--take", "m", "--frames", "2", "--out", str(tmp_path),
        "--sim", "ideal=true", "--sim", "deterministic=true", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    take = tmp_path / "m"
    res = rigctl(
        "render", str(take), "--disparity", str(take / "truth/disparity"), "--at", "1,1", "--out", str(tmp_path / "v")
    )
    assert res.returncode == 0, res.stderr
    assert "no comparison with the truth" in res.stderr
    assert len(list((tmp_path / "v").rglob("c1r1.png"))) == 2
