"""``take export``, ``depth``, ``process`` and ``rectify`` had no up-front disk-space check: a run on a file system
too small for it wrote until the disk was full, part of the way through. Each now holds an estimate of what it will
write (every picture as if uncompressed) against the free space of --out's file system before it writes anything, and
refuses in one line with exit 4 (the destination cannot take it), as ``render`` does. The free space is given
here (rigctl.diskspace.free_bytes replaced), never read from this machine's disk."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from reliab_support import make_tiny  # type: ignore[import-not-found]

import rigctl.diskspace
from rigctl.cli.main import main
from rigctl.depth.export import outputs_bytes
from rigctl.errors import EXIT_DEVICE
from rigctl.rectification.rectify import rectified_bytes, tree_bytes
from rigctl.take.export import BYTES_PER_PIXEL, FILE_BYTES
from rigctl.take.reader import TakeReader


@pytest.fixture(scope="module")
def tiny(module_tmp: Callable[[str], Path]) -> tuple[Path, Path]:
    return make_tiny(module_tmp("space"))


def free_space(monkeypatch: pytest.MonkeyPatch) -> tuple[list[Path], list[int]]:
    """The folders asked about, and the free space to answer (set ``given[0]``)."""
    asked: list[Path] = []
    given = [0]

    def free(folder: Path) -> int:
        asked.append(folder)
        return given[0]

    monkeypatch.setattr(rigctl.diskspace, "free_bytes", free)
    return asked, given


def written(out: Path) -> int:
    return sum(f.stat().st_size for f in out.rglob("*") if f.is_file())


def refused_then_run(
    argv: list[str], out: Path, need: int, what: str, given: list[int], asked: list[Path],
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    """One byte short of ``need``: one line, exit 4, nothing made; then exactly ``need``: it runs, within it."""
    given[0] = need - 1
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_DEVICE and len(err) == 1, err
    assert f": --out {out}: about " in err[0] and f"needed for {what}, " in err[0], err[0]
    assert "free on its file system; free some space or choose another --out" in err[0], err[0]
    assert asked == [out] and not out.parent.exists()  # refused before any file: the folder made for it is gone
    given[0] = need
    assert main(argv) == 0, capsys.readouterr().err
    assert 0 < written(out) <= need


@pytest.mark.parametrize("fmt", ["png", "exr"])
def test_an_export_the_disk_cannot_hold_is_refused_before_writing(
    tiny: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    fmt: str,
) -> None:  # fmt: skip
    take = tiny[0]
    asked, given = free_space(monkeypatch)
    reader = TakeReader(take)
    w, h = reader.width, reader.height
    out = tmp_path / "new" / "x"
    need = 18 * (w * h * BYTES_PER_PIXEL[fmt] + FILE_BYTES)  # frame sets 1-2, nine cameras
    argv = ["take", "export", str(take), "--out", str(out), "--frames", "1-2", "--format", fmt, "--quiet"]
    refused_then_run(argv, out, need, f"18 pictures of {w}x{h} ({fmt.upper()})", given, asked, capsys)


@pytest.mark.parametrize("formats", [("exr",), ("exr", "pfm", "png")])
@pytest.mark.parametrize("verb", [["depth"], ["process", "--workers", "1"]])
def test_a_depth_or_process_run_the_disk_cannot_hold_is_refused_before_writing(
    tiny: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    verb: list[str], formats: tuple[str, ...],
) -> None:  # fmt: skip
    """``process`` as ``depth``: what its chunks will write, checked on the client before any worker starts."""
    rect = tiny[1]
    asked, given = free_space(monkeypatch)
    reader = TakeReader(rect)
    w, h = reader.width, reader.height
    out = tmp_path / "new" / "d"
    need = outputs_bytes(4, w, h, formats)  # frame sets 0 and 1 of two cameras, in the formats asked for
    asked_for = ["--formats", ",".join(formats)] if len(formats) > 1 else []  # the EXR alone unless asked
    argv = [verb[0], str(rect), "--out", str(out), "--frames", "0-1", "--cameras", "r1c1", "r1c2", "--preset",
            "fast", *verb[1:], *asked_for, "--quiet"]  # fmt: skip
    what = f"2 cameras' depth in 2 frame sets at {w}x{h} ({' + '.join(f.upper() for f in formats)})"
    refused_then_run(argv, out, need, what, given, asked, capsys)
    if verb[0] == "process":  # a second run finds every frame set whole: nothing to write, nothing to find room for
        given[0] = 0
        assert main(argv) == 0, capsys.readouterr().err


def test_a_rectify_the_disk_cannot_hold_is_refused_before_writing(
    tiny: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    take, rect = tiny
    asked, given = free_space(monkeypatch)
    made = TakeReader(rect)  # the same take rectified with the same calibration: its size and frame count
    frames = sum(len(made.index[n]) for n in made.names)
    need = rectified_bytes(frames, made.width, made.height, len(made.names)) + tree_bytes(take / "truth")
    out = tmp_path / "new" / "r"
    argv = ["rectify", str(take), "--calibration", str(take / "truth/calibration.yaml"), "--out", str(out), "--quiet"]
    what = f"{frames} rectified frames of {made.width}x{made.height} (8-bit BGR) and the truth"
    refused_then_run(argv, out, need, what, given, asked, capsys)
