"""``--frames`` of every verb that takes it is read and checked the same way (rigctl.take.framesets): a range
that runs past the take's frame sets is refused in one line naming --frames and the frame sets the take has
(exit 2), before any output is made; none shrinks it to fit."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from hostile_support import one_line  # type: ignore[import-not-found]
from tests_support import run_rigctl  # type: ignore[import-not-found]

from rigctl.errors import EXIT_USAGE


@pytest.fixture(scope="module")
def ideal(module_tmp: Callable[[str], Path]) -> Path:
    """The README's small ideal take: three frame sets, its truth disparity in truth/disparity."""
    root = module_tmp("frames-option")
    res = run_rigctl(
        "record", "--take", "ideal", "--frames", "3", "--sim", "ideal=true", "--sim", "deterministic=true",
        "--out", str(root),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return root / "ideal"


def argv(verb: str, take: Path, out: Path, frames: str) -> list[str]:
    disparity = str(take / "truth" / "disparity")
    return {
        "take export": ["take", "export", str(take), "--out", str(out)],
        "render": ["render", str(take), "--disparity", disparity, "--at", "1,1", "--out", str(out)],
        "leave-one-out": ["render", str(take), "--disparity", disparity, "--leave-one-out", "--cameras", "r1c1"],
        "depth": ["depth", str(take), "--out", str(out), "--preset", "fast"],
        "process": ["process", str(take), "--out", str(out), "--workers", "1"],
        "miv export": ["miv", "export", str(take), disparity, "--out", str(out)],
    }[verb] + ["--frames", frames]


VERBS = ["take export", "render", "leave-one-out", "depth", "process", "miv export"]


@pytest.mark.parametrize("frames", ["0-3", "2-9", "3", "0-99999999999999999999"])
@pytest.mark.parametrize("verb", VERBS)
def test_frames_past_the_take_are_refused_by_every_verb(ideal: Path, tmp_path: Path, verb: str, frames: str) -> None:
    out = tmp_path / "out"
    line = one_line(run_rigctl(*argv(verb, ideal, out, frames)), EXIT_USAGE, f"--frames {frames}:", str(ideal))
    assert "frame set 3 (its " in line and "frame sets: 0-2)" in line, line
    assert not out.exists(), "an output was made before --frames was refused"


@pytest.mark.parametrize(("frames", "said"), [("x", "expected N or A-B"), ("2-1", "need 0 <= A <= B"), ("-1", "")])
@pytest.mark.parametrize("verb", VERBS)
def test_a_malformed_frames_is_the_same_line_for_every_verb(
    ideal: Path, tmp_path: Path, verb: str, frames: str, said: str
) -> None:
    one_line(run_rigctl(*argv(verb, ideal, tmp_path / "out", frames)), EXIT_USAGE, "--frames", said)


def test_frames_within_the_take_still_work(ideal: Path, tmp_path: Path) -> None:
    res = run_rigctl(*argv("take export", ideal, tmp_path / "e", "1-2"))
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "e").iterdir()) == ["000001", "000002", "export.json"]


@pytest.fixture(scope="module")
def grid_folder(ideal: Path) -> Path:
    """Frame set 1 of the ideal take as a grid folder (one picture per camera), through MIV content."""
    content, grids = ideal.parent / "miv", ideal.parent / "grids"
    res = run_rigctl("miv", "export", str(ideal), str(ideal / "truth" / "disparity"), "--out", str(content))
    assert res.returncode == 0, res.stderr
    res = run_rigctl("miv", "import", str(content / "cameras.json"), "--out", str(grids), "--frames", "1")
    assert res.returncode == 0, res.stderr
    return grids / "000001"


@pytest.mark.parametrize("verb", ["depth", "render"])
def test_a_grid_folder_is_frame_set_0_for_depth_as_for_render(grid_folder: Path, tmp_path: Path, verb: str) -> None:
    """A grid folder is one frame set: depth ignored --frames 5 on it where render refused it."""
    out = tmp_path / "out"
    disparity = str(grid_folder / "truth")
    cmd = {
        "depth": ["depth", str(grid_folder), "--out", str(out), "--preset", "fast", "--cameras", "r1c1"],
        "render": ["render", str(grid_folder), "--disparity", disparity, "--at", "1,1", "--out", str(out)],
    }[verb]
    one_line(run_rigctl(*cmd, "--frames", "5"), EXIT_USAGE, "--frames 5:", "frame sets: 0)")
    assert not out.exists()
