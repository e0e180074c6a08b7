"""Progress as the operator sees it: ``take export`` and ``render`` run under a real pseudo-terminal (a real
rigctl process, pty.fork) draw a bar with the count, the rate, the time elapsed and the time remaining; the
same commands into a pipe end with one summary line on stderr, and ``--quiet`` leaves stderr empty."""

from __future__ import annotations

import os
import pty
import re
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import rigctl_command

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def on_a_terminal(*argv: str) -> tuple[int, str]:
    """Run rigctl with stdin, stdout and stderr on a new pseudo-terminal; its exit status and what the terminal
    showed, escape sequences taken out and each redraw (carriage return) on a line of its own."""
    pid, fd = pty.fork()
    if pid == 0:  # the child: the installed console script, as a user at a terminal runs it
        os.execve(rigctl_command()[0], [*rigctl_command(), *argv], {**os.environ, "COLUMNS": "150"})
    out = b""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except OSError:  # EIO: the child closed the terminal
            break
        if not chunk:
            break
        out += chunk
    os.close(fd)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), ANSI.sub("", out.decode(errors="replace")).replace("\r", "\n")


def assert_bar_with_time_left(screen: str, unit: str, total: int) -> None:
    """Some redraw before the end shows k/total with a time remaining (not the -:-- of no estimate yet), and
    the last one shows the whole count."""
    bars = re.findall(rf"(\d+)/{total} {unit} +([\d.]+|-)/s +(\d+:\d\d) elapsed, (\S+) left", screen)
    assert bars, screen
    midway = [b for b in bars if 0 < int(b[0]) < total and re.fullmatch(r"\d+:\d\d", b[3])]
    assert midway, bars
    assert any(int(b[0]) == total for b in bars), bars


def assert_one_prefix(exr: Path, ours: set[str]) -> None:
    """Every attribute of ours in the file's own header is under the one prefix (none of rigctl. or rigctl_)."""
    import OpenEXR

    names = {k for k in OpenEXR.File(str(exr), header_only=True).header() if k.lower().startswith("rigctl")}
    assert names == ours, names


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    """An ideal simulated take of four frame sets (with the simulator's other defaults: motion on)."""
    out = module_tmp("takes")
    res = subprocess.run(
        [*rigctl_command(), "record", "sim-3x3", "--take", "ideal", "--frames", "4", "--sim", "ideal=true",
         "--sim", "deterministic=true", "--out", str(out), "--quiet"],
        capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert res.stderr.strip() == "" or "preflight" in res.stderr, res.stderr  # --quiet: no progress line
    return out / "ideal"


def test_take_export_shows_a_bar_with_time_left_on_a_terminal_and_one_line_elsewhere(
    take: Path, tmp_path: Path
) -> None:
    code, screen = on_a_terminal("take", "export", str(take), "--out", str(tmp_path / "tty"), "--format", "exr")
    assert code == 0, screen
    assert_bar_with_time_left(screen, "frame sets", 4)
    exrs = sorted((tmp_path / "tty").glob("*/*.exr"))
    assert len(exrs) == 36
    assert_one_prefix(exrs[0], {"rigctl:camera", "rigctl:frame_set"})
    piped = subprocess.run(
        [*rigctl_command(), "take", "export", str(take), "--out", str(tmp_path / "pipe"), "--frames", "0-1"],
        capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert piped.returncode == 0, piped.stderr
    lines = piped.stderr.splitlines()
    assert len(lines) == 1 and re.fullmatch(
        r"exporting ideal: 2 of 2 frame sets in \d+\.\d s \(\d+\.\d\d frame sets/s\)", lines[0]
    ), lines
    assert "━" not in piped.stderr and "18 images from 2 frame sets" in piped.stdout


def test_render_shows_a_bar_with_time_left_on_a_terminal_and_no_progress_with_quiet(take: Path, tmp_path: Path) -> None:
    disparity = str(take / "truth" / "disparity")
    path = ["--path", "0,1", "2,1", "--steps", "6", "--frames", "0"]
    code, screen = on_a_terminal("render", str(take), "--disparity", disparity, *path, "--out", str(tmp_path / "a"))
    assert code == 0, screen
    assert_bar_with_time_left(screen, "views", 6)
    views = sorted((tmp_path / "a" / "000000").glob("path_*.exr"))
    assert len(views) == 6
    assert_one_prefix(views[0], {"rigctl:position", "rigctl:sources"})
    quiet = subprocess.run(
        [*rigctl_command(), "render", str(take), "--disparity", disparity, *path, "--out", str(tmp_path / "b"),
         "--quiet"],
        capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    # only the warning that a take with motion has no truth view to compare with: no bar, no summary line
    assert quiet.returncode == 0 and "━" not in quiet.stderr and "render ideal" not in quiet.stderr, quiet.stderr
    assert "wrote 6 view(s)" in quiet.stdout
