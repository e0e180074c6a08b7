"""Issue 25: each writing command killed (SIGKILL, SIGTERM) at several exact points, then run again with the
same command. Every file published under a final name must be whole at every instant, the re-run must
finish, and its result must equal an uninterrupted run's. The kill points are system calls of the real
process (tests/fault_runner.py): a file written under its temporary name (``fsync``), a rename about to
publish it (``replace``), bytes going into a rectified take's essence (``write``)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from reliab_support import make_tiny, published, rigctl  # type: ignore[import-not-found]

from rigctl.publish import PARTIAL_SUFFIX, TEMP_SUFFIX
from rigctl.take.check import check_take

RUNNER = Path(__file__).resolve().parents[1] / "fault_runner.py"


@pytest.fixture(scope="module")
def tiny(module_tmp: Callable[[str], Path]) -> dict[str, Path]:
    root = module_tmp("fault")
    take, rect = make_tiny(root)
    (rect / "truth" / "settings.yaml").unlink()  # no simulator comparisons: render stays quick
    res = rigctl("depth", str(rect), "--out", str(root / "disp"), "--preset", "fast")
    assert res.returncode == 0, res.stderr
    res = rigctl("miv", "export", str(rect), str(root / "disp"), "--out", str(root / "content"))
    assert res.returncode == 0, res.stderr
    return {"take": take, "rect": rect, "disp": root / "disp", "root": root, "content": root / "content"}


def command(verb: str, paths: dict[str, Path], out: Path) -> list[str]:
    if verb == "export":
        return ["take", "export", str(paths["take"]), "--out", str(out)]
    if verb == "export-exr":
        return ["take", "export", str(paths["take"]), "--out", str(out), "--format", "exr"]
    if verb == "rectify":
        calibration = str(paths["take"] / "truth/calibration.yaml")
        return ["rectify", str(paths["take"]), "--calibration", calibration, "--out", str(out)]
    if verb == "miv-export":
        return ["miv", "export", str(paths["rect"]), str(paths["disp"]), "--out", str(out)]
    if verb == "miv-import":
        return ["miv", "import", str(paths["content"] / "cameras.json"), "--out", str(out)]
    if verb == "depth":
        return ["depth", str(paths["rect"]), "--out", str(out), "--preset", "fast"]
    return ["render", str(paths["rect"]), "--disparity", str(paths["disp"]), "--at", "1,1", "--out", str(out)]


def comparable(files: dict[str, bytes]) -> dict[str, bytes]:
    """Outputs that must be the same in every run (reports hold timings, a take's manifest its paths)."""
    return {k: v for k, v in files.items() if not k.endswith(("report.json", "take.yaml"))}


CASES = [
    ("export", "fsync", 1, "KILL"),
    ("export", "fsync", 14, "TERM"),
    ("export", "replace", 27, "KILL"),
    ("export-exr", "replace", 9, "TERM"),
    ("rectify", "write", 7, "KILL"),
    ("rectify", "write", 40, "TERM"),
    ("rectify", "replace", 1, "KILL"),  # the partial take's manifest about to be published
    ("rectify", "replace", 2, "KILL"),  # the whole take about to be renamed to its name
    ("depth", "fsync", 3, "KILL"),
    ("depth", "replace", 50, "TERM"),
    ("render", "fsync", 2, "KILL"),
    ("render", "replace", 5, "TERM"),
    ("miv-export", "fsync", 2, "KILL"),  # the first camera's YUV files written, the rest not
    ("miv-export", "replace", 3, "TERM"),  # the whole content about to be renamed to its name
    ("miv-import", "fsync", 3, "KILL"),  # a grid folder half written
    ("miv-import", "replace", 12, "TERM"),  # the import about to be renamed to its name
]


@pytest.fixture(scope="module")
def reference(tiny: dict[str, Path]) -> dict[str, dict[str, bytes]]:
    """Each command's output from an uninterrupted run."""
    out = {}
    for verb in sorted({c[0] for c in CASES}):
        dest = tiny["root"] / f"ref-{verb}"
        res = rigctl(*command(verb, tiny, dest))
        assert res.returncode == 0, res.stderr
        out[verb] = comparable(published(dest))
    return out


@pytest.mark.parametrize(("verb", "call", "nth", "sig"), CASES, ids=["-".join(map(str, c)) for c in CASES])
def test_a_killed_command_leaves_only_whole_files_and_the_same_command_finishes(
    tiny: dict[str, Path],
    reference: dict[str, dict[str, bytes]],
    tmp_path: Path,
    verb: str,
    call: str,
    nth: int,
    sig: str,
) -> None:
    out = tmp_path / "out"
    argv = command(verb, tiny, out)
    killed = subprocess.run(
        [sys.executable, str(RUNNER), call, str(nth), sig, "--", *argv],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert killed.returncode == -{"KILL": 9, "TERM": 15}[sig], (killed.returncode, killed.stderr)
    if verb in ("rectify", "miv-import", "miv-export"):  # built under a partial name, renamed once whole
        assert not out.exists(), "a half-written folder carries the name asked for"
    else:
        published(out)  # every file at its final name is whole
    res = rigctl(*argv)
    assert res.returncode == 0, res.stderr
    assert comparable(published(out)) == reference[verb]
    assert not list(tmp_path.rglob(f"*{TEMP_SUFFIX}")) and not list(tmp_path.glob(f".*{PARTIAL_SUFFIX}"))
    if verb == "rectify":
        assert check_take(out).ok


@pytest.mark.parametrize("nth", [1, 2, 3, 4])
def test_a_demo_killed_while_clearing_a_finished_one_is_left_unfinished(tmp_path: Path, nth: int) -> None:
    """demo --fresh cleared a finished demo in directory order: killed there, it could leave report.md beside
    half its figures (a "finished" demo the next run refuses without --fresh) or the figures without the
    marker (a folder the next run refuses for ever). Killed at any removal, the folder is now whole or
    unfinished (marker, no report), which the next demo replaces without asking."""
    out = tmp_path / "demo"
    (out / "takes" / "calibration").mkdir(parents=True)
    files = {".rigctl-demo": "rigctl demo\n", "report.md": "# report\n", "calibration.yaml": "spec: 1\n"}
    files |= {"depth.png": "png", "takes/calibration/take.yaml": "spec: 1\n"}
    for name, text in files.items():
        (out / name).write_text(text)
    killed = subprocess.run(
        [sys.executable, str(RUNNER), "unlink", str(nth), "KILL", "--", "demo", "--out", str(out), "--fresh"],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert killed.returncode == -9, (killed.returncode, killed.stderr)
    left = {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()}
    assert left == set(files) or (".rigctl-demo" in left and "report.md" not in left) or not left, left
