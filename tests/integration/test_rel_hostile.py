"""Hostile takes and output folders for take, miv, usd and process (h-rel): one line, a documented exit code."""

from __future__ import annotations

import json
import shutil
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hostile_support import one_line  # type: ignore[import-not-found]
from reliab_support import edit_manifest, record_tiny, rigctl  # type: ignore[import-not-found]


@pytest.fixture(scope="module")
def tiny(module_tmp: Callable[[str], Path]) -> Path:
    """A recorded take of the simulated 3x3 rig, 2 frame sets of 96x54."""
    return record_tiny(module_tmp("rel"), "t", 2, "motion=false")


def copy(take: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(take, tmp_path / "t"))


@pytest.mark.parametrize("verb", ["info", "check", "export"])
def test_camera_file_in_a_symlink_loop_is_one_line(tiny: Path, tmp_path: Path, verb: str) -> None:
    take = copy(tiny, tmp_path)
    essence = take / "cameras" / "r0c0.essence"
    essence.unlink()
    essence.symlink_to("r0c0.essence")  # a link to itself: resolving it loops
    extra = ["--out", str(tmp_path / "out")] if verb == "export" else []
    res = rigctl("take", verb, str(take), *extra)
    if verb == "check":  # check lists its problems, then counts them
        assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
        assert "r0c0.essence" in res.stderr and "loop of symbolic links" in res.stderr, res.stderr
    else:
        one_line(res, 3, "r0c0.essence", "loop of symbolic links")


@pytest.fixture(scope="module")
def ideal(module_tmp: Callable[[str], Path]) -> Path:
    """An ideal tiny take: already rectified, with its true disparity."""
    return record_tiny(module_tmp("rel-ideal"), "ideal", 1, "ideal=true", "motion=false")


@pytest.fixture(scope="module")
def content(ideal: Path) -> Path:
    """MIV content of the ideal take and its true disparity."""
    take = ideal
    out = take.parent / "content"
    res = rigctl("miv", "export", str(take), str(take / "truth" / "disparity"), "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out


def edited_content(content: Path, tmp_path: Path, edit: Callable[[list[dict[str, Any]]], None]) -> Path:
    """A copy of ``content`` (YUV files linked) whose cameras.json is changed by ``edit(cameras)``."""
    copy = tmp_path / "content"
    copy.mkdir()
    for f in content.iterdir():
        (copy / f.name).symlink_to(f)
    (copy / "cameras.json").unlink()
    doc = json.loads((content / "cameras.json").read_text())
    edit(doc["cameras"])
    (copy / "cameras.json").write_text(json.dumps(doc))
    return copy / "cameras.json"


def _set(i: int, key: str, value: object) -> Callable[[list[dict[str, Any]]], None]:
    return lambda cams: cams[i].__setitem__(key, value)


@pytest.mark.parametrize(
    ("edit", "fragment"),
    [
        # two cameras named alike read one camera's files: a grid position showed another camera's view, exit 0
        (lambda cams: cams[1].__setitem__("Name", cams[0]["Name"]), "is used twice"),
        (_set(0, "Name", "r0c0\0"), "no usable Name"),  # a NUL byte: ValueError traceback from open()
        # a Name is part of the file names read beside cameras.json: never a path out of the content's folder
        (_set(0, "Name", "../../r0c0"), "no usable Name"),
        (_set(0, "Name", "/tmp/r0c0"), "no usable Name"),
        (_set(0, "Depth_range", [1e-300, 3.0]), "Depth_range"),  # disparity overflowed to inf, exit 0
        (_set(0, "Position", [1e308, 0.0, 0.0]), "Position"),  # 'inf mm' off the plane, and a RuntimeWarning
    ],
    ids=["duplicate-name", "nul-name", "parent-name", "absolute-name", "near-1e-300", "position-1e308"],
)
def test_hostile_camera_json_is_one_line(
    content: Path, tmp_path: Path, edit: Callable[[list[dict[str, Any]]], None], fragment: str
) -> None:
    cameras = edited_content(content, tmp_path, edit)
    res = rigctl("miv", "import", str(cameras), "--out", str(tmp_path / "grid"))
    one_line(res, 3, "cameras.json", fragment)
    assert "inf" not in res.stderr.replace("info", "") and "Warning" not in res.stderr
    assert not (tmp_path / "grid").exists()


@pytest.mark.parametrize("where", ["proc", "under-a-file"])
def test_usd_into_a_place_that_cannot_be_written_is_one_line(ideal: Path, tmp_path: Path, where: str) -> None:
    """pxr raised its own Tf.ErrorException: a traceback, exit 1."""
    (tmp_path / "file").write_text("x")
    out = Path("/proc/rigctl-rel.usda") if where == "proc" else tmp_path / "file" / "rig.usda"
    res = rigctl("usd", str(ideal), "--out", str(out))
    one_line(res, 4, str(out))


def test_usd_is_published_whole_and_never_replaced(ideal: Path, tmp_path: Path) -> None:
    for suffix in (".usda", ".usdc"):
        out = tmp_path / f"rig{suffix}"
        assert rigctl("usd", str(ideal), "--out", str(out)).returncode == 0
        first = out.read_bytes()
        assert first.startswith(b"#usda 1.0" if suffix == ".usda" else b"PXR-USDC")
        one_line(rigctl("usd", str(ideal), "--out", str(out)), 2, "already exists")
        assert out.read_bytes() == first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.usda", "rig.usdc"]  # no temporary file left


@pytest.mark.parametrize("json_out", [False, True])
def test_plan_refuses_a_budget_that_puts_the_subject_beyond_1000_km(json_out: bool) -> None:
    """--budget 1e-300 solved near = far = 4.8e149 m for a subject 1 m deep (its depth lost in rounding), exit 0."""
    res = rigctl("plan", "sim-3x3", "--budget", "1e-300", *(["--json"] if json_out else []))
    one_line(res, 2, "--budget 1e-300", "beyond 1,000 km")
    assert res.stdout == ""


@pytest.mark.parametrize(
    "argv",
    [
        ["take", "export", "{take}", "--out", "{take}"],
        ["take", "export", "{take}", "--out", "{take}/export"],
        ["process", "{take}", "--out", "{take}/depth"],
        ["miv", "export", "{take}", "{take}/truth/disparity", "--out", "{take}/miv"],
    ],
    ids=["export-into-take", "export-under-take", "process-under-take", "miv-under-take"],
)
def test_an_output_inside_the_take_is_refused_before_any_work(ideal: Path, tmp_path: Path, argv: list[str]) -> None:
    """They wrote their pictures into the recording, exit 0: the take then held files no camera recorded."""
    take = copy(ideal, tmp_path)
    before = sorted(p.relative_to(take) for p in take.rglob("*"))
    res = rigctl(*(a.format(take=take) for a in argv))
    one_line(res, 2, "is inside the take")
    assert sorted(p.relative_to(take) for p in take.rglob("*")) == before


@pytest.mark.parametrize(("row", "value"), [(0, [0.0, 0.0, 47.5]), (0, [1e300, 0.0, 47.5]), (1, [0.0, 183.8, 1e300])])
def test_a_rectified_take_whose_camera_matrix_is_no_camera_is_refused(
    ideal: Path, tmp_path: Path, row: int, value: list[float]
) -> None:
    """fx 0 wrote a USD stage with horizontalAperture = inf, exit 0; the take read as sound."""
    take = copy(ideal, tmp_path)
    edit_manifest(take, lambda m: m["rectification"]["K"].__setitem__(row, value))
    out = tmp_path / "rig.usda"
    one_line(rigctl("usd", str(take), "--out", str(out)), 3, "take.yaml", "camera matrix K")
    assert not out.exists()
    one_line(rigctl("take", "info", str(take)), 3, "camera matrix K")


def test_process_says_nothing_when_another_dask_holds_port_8787(ideal: Path, tmp_path: Path) -> None:
    """The local cluster's HTTP server took Dask's default port: with it busy (another cluster on the machine) a
    successful run printed 'UserWarning: Port 8787 is already in use' and three more lines on stderr."""
    holder = socket.socket()
    try:
        holder.bind(("127.0.0.1", 8787))
        holder.listen()
    except OSError:
        pass  # held already by someone else: the case itself
    try:
        out = str(tmp_path / "p")
        res = rigctl("process", str(ideal), "--out", out, "--workers", "1", "--quiet", "--preset", "fast")
    finally:
        holder.close()
    assert res.returncode == 0, res.stderr
    assert res.stderr == ""
