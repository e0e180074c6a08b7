"""Novel views on an ideal simulated presenter take: leave-one-out quality with the true disparity and with
our depth, a view between cameras against the simulator's own render there, files on disk, a missing
source camera, and disparity folders that do not match the take."""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from tests_support import run_rigctl


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    out = module_tmp("render")
    res = run_rigctl(
        "record",
        "--take",
        "ideal",
        "--frames",
        "1",
        "--out",
        str(out),
        "--sim",
        "ideal=true",
        "--sim",
        "motion=false",
        "--force",
    )
    assert res.returncode == 0, res.stderr
    return out / "ideal"


@pytest.fixture(scope="module")
def our_depth(take: Path) -> Path:
    out = take.parent / "depth"
    res = run_rigctl("depth", str(take), "--out", str(out), "--near", "1.95", "--far", "3.0", "--json")
    assert res.returncode == 0, res.stderr
    return out


def loo(take: Path, disparity: Path, *cams: str, warning: str = "") -> dict[str, dict]:
    res = run_rigctl(
        "render", str(take), "--disparity", str(disparity), "--leave-one-out", "--cameras", *cams, "--json"
    )
    assert res.returncode == 0, res.stderr
    assert warning in res.stderr
    rows = json.loads(res.stdout)["leave_one_out"]
    assert {"frame", "camera", "psnr_db", "ssim", "ivpsnr_db", "pixels"} <= set(rows[0])
    return {r["camera"]: r for r in rows}


def test_leave_one_out_of_r1c1_with_true_disparity_reaches_33_db(take: Path) -> None:
    rows = loo(take, take / "truth" / "disparity", "r1c1", "r0c0")
    r = rows["r1c1"]
    assert r["psnr_db"] >= 33.0 and r["ssim"] > 0.95, r
    assert r["ivpsnr_db"] > r["psnr_db"] + 3, r  # it forgives the sub-pixel shifts of view synthesis
    assert "r1c1" not in r["sources"] and len(r["sources"]) == 4  # never from itself
    assert r["pixels"] > 100_000  # the keyed subject, not the whole image (518400)
    assert r["pixels"] < 300_000


def test_leave_one_out_with_our_depth_reaches_30_db(take: Path, our_depth: Path) -> None:
    r = loo(take, our_depth, "r1c1")["r1c1"]
    assert r["psnr_db"] >= 30.0, r


def test_a_wrong_disparity_scores_far_worse(take: Path, tmp_path: Path) -> None:
    """The score measures the disparity: the truth shifted by 3 px loses many dB."""
    from rigctl.pfm import read_pfm, write_pfm

    bad = tmp_path / "bad" / "000000"
    bad.mkdir(parents=True)
    for p in (take / "truth" / "disparity" / "000000").glob("*.pfm"):
        write_pfm(bad / p.name, read_pfm(p) + 3.0)
    good = loo(take, take / "truth" / "disparity", "r1c1")["r1c1"]["psnr_db"]
    worse = loo(take, tmp_path / "bad", "r1c1")["r1c1"]["psnr_db"]
    assert worse < good - 6.0, (good, worse)


def test_full_frame_score_sees_depth_painted_over_the_screen(take: Path, tmp_path: Path) -> None:
    """The screen painted at the subject's distance (every pixel with no truth given the subject's median
    disparity): the full-frame PSNR (premultiplied, every pixel) falls with the subject's."""
    from rigctl.pfm import read_pfm, write_pfm

    painted = tmp_path / "painted" / "000000"
    painted.mkdir(parents=True)
    for p in (take / "truth" / "disparity" / "000000").glob("*.pfm"):
        d = read_pfm(p)
        write_pfm(painted / p.name, np.where(np.isfinite(d), d, np.median(d[np.isfinite(d)])).astype(np.float32))
    good = loo(take, take / "truth" / "disparity", "r1c1")["r1c1"]
    bad = loo(take, tmp_path / "painted", "r1c1")["r1c1"]
    print(f"truth: {good['psnr_db']} / {good['full_frame_psnr_db']} dB; painted: {bad['psnr_db']} / "
          f"{bad['full_frame_psnr_db']} dB (subject / full frame)")  # fmt: skip
    assert good["full_frame_psnr_db"] > good["psnr_db"]  # the screen, keyed out in both, agrees
    assert bad["full_frame_psnr_db"] < good["full_frame_psnr_db"] - 3.0


def test_view_between_cameras_is_within_2_db_of_leave_one_out(take: Path, tmp_path: Path) -> None:
    truth = take / "truth" / "disparity"
    out = tmp_path / "views"
    res = run_rigctl("render", str(take), "--disparity", str(truth), "--at", "1.5,1", "--out", str(out), "--json")
    assert res.returncode == 0, res.stderr
    view = json.loads(res.stdout)["views"][0]
    assert view["view"] == "c1.5r1" and "r1c1" in view["sources"] and "r1c2" in view["sources"]
    against = view["against_truth"]["psnr_db"]
    ref = loo(take, truth, "r1c1")["r1c1"]["psnr_db"]
    assert against >= ref - 2.0, (against, ref)
    # the files: 8-bit RGBA PNG and float RGBA EXR, alpha from the key (transparent screen, opaque body)
    png = cv2.imread(str(out / "000000" / "c1.5r1.png"), cv2.IMREAD_UNCHANGED)
    assert png.shape == (540, 960, 4)
    alpha = png[..., 3]
    assert 0.5 < np.mean(alpha == 0) < 0.9 and alpha[270, 480] == 255
    from rigctl.exr import REC709_CHROMATICITIES, bt709_to_linear, read_exr

    channels, header = read_exr(out / "000000" / "c1.5r1.exr")
    a = channels["A"]
    assert np.allclose(a, alpha / 255.0, atol=1 / 255 + 1e-6)
    # scene-linear and premultiplied, as NUKE reads an EXR: the PNG's code values decoded, times A
    rgb = cv2.cvtColor(png, cv2.COLOR_BGRA2RGBA)[..., :3] / 255.0
    body = alpha == 255
    assert np.allclose(channels["RGB"][body], bt709_to_linear(rgb[body]), atol=0.01)
    assert np.allclose(header["chromaticities"], REC709_CHROMATICITIES, atol=1e-6)


def test_stereo_pair_is_ipd_apart_and_shows_parallax(take: Path, tmp_path: Path) -> None:
    out = tmp_path / "stereo"
    res = run_rigctl(
        "render", str(take), "--disparity", str(take / "truth" / "disparity"), "--at", "1,1", "--stereo", "0.06",
        "--out", str(out), "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    views = {v["view"]: v for v in json.loads(res.stdout)["views"]}
    # 0.06 m through the rig's 0.12 m spacing: half a grid unit apart
    assert views["c1r1_L"]["col"] == pytest.approx(0.75) and views["c1r1_R"]["col"] == pytest.approx(1.25)
    left = cv2.imread(str(out / "000000" / "c1r1_L.png"), cv2.IMREAD_UNCHANGED)[..., 3] > 127
    right = cv2.imread(str(out / "000000" / "c1r1_R.png"), cv2.IMREAD_UNCHANGED)[..., 3] > 127
    body = slice(50, 450)  # above the desk, which spans the whole width
    shift = np.nonzero(right[body])[1].mean() - np.nonzero(left[body])[1].mean()
    assert abs(shift) > 5  # the subject moves between the eyes
    for v in views.values():
        assert v["against_truth"]["psnr_db"] > 30


def test_path_writes_a_numbered_sequence(take: Path, tmp_path: Path) -> None:
    out = tmp_path / "path"
    res = run_rigctl(
        "render", str(take), "--disparity", str(take / "truth" / "disparity"), "--path", "0,1", "2,1",
        "--steps", "3", "--out", str(out),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (out / "000000").glob("*.png")) == [f"path_000{i}.png" for i in range(3)]
    assert "earlier run" not in res.stderr
    res = run_rigctl(
        "render", str(take), "--disparity", str(take / "truth" / "disparity"), "--path", "0,1", "2,1",
        "--steps", "2", "--out", str(out),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "holds 1 view(s) from an earlier run that this one does not write over (path_0002)" in res.stderr


def test_a_missing_source_camera_is_left_out(take: Path, tmp_path: Path) -> None:
    disp = tmp_path / "disp"
    shutil.copytree(take / "truth" / "disparity", disp)
    (disp / "000000" / "r1c2.pfm").unlink()
    r = loo(take, disp, "r1c1", warning="no disparity for r1c2: not used as sources")["r1c1"]
    assert "r1c2" not in r["sources"] and len(r["sources"]) == 4
    assert r["psnr_db"] >= 30.0


def test_disparity_of_another_size_is_one_clear_line(take: Path, tmp_path: Path) -> None:
    from rigctl.pfm import write_pfm

    disp = tmp_path / "small" / "000000"
    disp.mkdir(parents=True)
    for name in ("r1c0", "r1c1", "r1c2"):
        write_pfm(disp / f"{name}.pfm", np.full((270, 480), 20.0, np.float32))
    res = run_rigctl("render", str(take), "--disparity", str(tmp_path / "small"), "--leave-one-out")
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "small/000000/r1c" in lines[0] and "480x270" in lines[0] and "960x540" in lines[0], lines
    assert "Traceback" not in res.stderr


def test_disparity_of_other_frames_is_one_clear_line(take: Path, tmp_path: Path) -> None:
    other = tmp_path / "other" / "000007"
    other.mkdir(parents=True)
    res = run_rigctl("render", str(take), "--disparity", str(tmp_path / "other"), "--at", "1,1", "--out", str(tmp_path))
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "no disparity for frame 0" in lines[0], lines


def test_bad_positions_and_modes_are_refused(take: Path, tmp_path: Path) -> None:
    truth = str(take / "truth" / "disparity")
    res = run_rigctl("render", str(take), "--disparity", truth, "--at", "1;1", "--out", str(tmp_path))
    assert res.returncode == 2 and "COL,ROW" in res.stderr
    res = run_rigctl("render", str(take), "--disparity", truth, "--out", str(tmp_path))
    assert res.returncode == 2 and "--leave-one-out" in res.stderr


def one_line(res: object, *words: str) -> None:
    """A non-zero exit with one line on stderr holding every one of ``words``, and no traceback."""
    assert res.returncode != 0  # type: ignore[attr-defined]
    lines = res.stderr.strip().splitlines()  # type: ignore[attr-defined]
    assert len(lines) == 1 and all(w in lines[0] for w in words), lines


def test_views_no_camera_can_see_are_refused(take: Path, tmp_path: Path) -> None:
    """Positions beyond the array and eye pairs metres apart (an IPD typed in millimetres) once wrote empty
    images with exit 0, or ended in a traceback (1e308): now one line each, and nothing is written."""
    truth = str(take / "truth" / "disparity")
    out = tmp_path / "out"
    for at in ("5,5", "-1.5,1", "1e308,0", "1,1e20"):
        res = run_rigctl("render", str(take), "--disparity", truth, f"--at={at}", "--out", str(out))
        one_line(res, "outside the array", "columns 0..2")
    res = run_rigctl("render", str(take), "--disparity", truth, "--at", "1,1", "--stereo", "10", "--out", str(out))
    one_line(res, "--stereo 10 m", "outside the array")
    res = run_rigctl("render", str(take), "--disparity", truth, "--path", "0,0", "9,0", "--out", str(out))
    one_line(res, "position 3.375,0", "outside the array")  # the first of the 9 steps beyond it
    assert not out.exists()  # refused before the output folder was made
    res = run_rigctl("render", str(take), "--disparity", truth, "--path", "0,0", "2,0", "--steps", "100000000",
                     "--out", str(out))  # fmt: skip
    one_line(res, "--steps 100000000: at most 10000")
    res = run_rigctl("render", str(take), "--disparity", truth, "--at=-0.5,2.5", "--out", str(out))
    assert res.returncode == 0, res.stderr  # half a spacing beyond the corner: the nearest cameras see it


def test_options_that_do_not_apply_and_positions_that_share_a_name_are_refused(take: Path, tmp_path: Path) -> None:
    """Options once ignored without a word (--cameras with --at, --steps with --at, --out with
    --leave-one-out, a camera named twice) and positions written to one file are one line each."""
    truth = str(take / "truth" / "disparity")
    out = str(tmp_path / "out")
    cases = [
        (["--at", "1,1", "--cameras", "r1c1", "--out", out], "--cameras applies to --leave-one-out"),
        (["--at", "1,1", "--steps", "3", "--out", out], "--steps applies to --path"),
        (["--leave-one-out", "--out", out], "--leave-one-out writes no images"),
        (["--leave-one-out", "--cameras", "r1c1", "--cameras", "r0c1", "r1c1"], "names r1c1 more than once"),
        (["--at", "1,1", "--at", "1.0000001,1", "--out", out], "would both be written as c1r1"),
    ]
    for args, words in cases:
        one_line(run_rigctl("render", str(take), "--disparity", truth, *args), words)
    assert not list((tmp_path / "out").rglob("*.png"))


def test_hostile_disparity_values_and_output_folders_are_one_line(take: Path, tmp_path: Path) -> None:
    """FLT_MAX as a 'no estimate' mark (some tools write it) once overflowed the renderer's fill in a
    traceback; an --out that is a file, or cannot be made, ended in a traceback too."""
    from rigctl.pfm import read_pfm, write_pfm

    disp = tmp_path / "disp"
    shutil.copytree(take / "truth" / "disparity", disp)
    d = read_pfm(disp / "000000" / "r1c0.pfm")
    d[:, : d.shape[1] // 2] = np.finfo(np.float32).max
    write_pfm(disp / "000000" / "r1c0.pfm", d)
    res = run_rigctl("render", str(take), "--disparity", str(disp), "--leave-one-out")
    one_line(res, "r1c0.pfm", "beyond the image's width (960 px)", "+inf")
    truth = str(take / "truth" / "disparity")
    afile = tmp_path / "afile"
    afile.write_text("not a folder")
    for out in (afile, afile / "sub", Path("/proc/nope")):
        res = run_rigctl("render", str(take), "--disparity", truth, "--at", "1,1", "--out", str(out))
        one_line(res, str(out), "cannot make the output folder")


def test_depth_check_of_one_camera_is_refused_before_computing(take: Path, tmp_path: Path) -> None:
    res = run_rigctl("depth", str(take), "--out", str(tmp_path / "d"), "--cameras", "r1c1", "--check")
    one_line(res, "--check", "at least two --cameras")
    assert not (tmp_path / "d").exists()


def test_depth_check_adds_leave_one_out_to_the_report(take: Path, tmp_path: Path) -> None:
    out = tmp_path / "depth"
    res = run_rigctl(
        "depth", str(take), "--out", str(out), "--near", "1.95", "--far", "3.0",
        "--cameras", "r1c0", "r1c1", "r1c2", "--check", "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    rows = json.loads((out / "report.json").read_text())["leave_one_out"]
    assert {r["camera"] for r in rows} == {"r1c0", "r1c1", "r1c2"}
    centre = next(r for r in rows if r["camera"] == "r1c1")
    assert sorted(centre["sources"]) == ["r1c0", "r1c2"] and centre["psnr_db"] > 28


def test_bench_render_reports_its_keys(tmp_path: Path) -> None:
    res = run_rigctl("bench", "render", "--size", "480x270", "--repeats", "1", "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    assert (r["width"], r["height"]) == (480, 270) and len(r["sources"]) >= 4 and r["stereo_pair_ms"] > 0
    assert r["quality"]["leave_one_out_r1c1"]["psnr_db"] >= 33
    # ratios of the median pair, rounded to two places
    assert r["ratio_to_paper"] == pytest.approx(r["stereo_pair_ms"] / (1000 / 90), abs=0.006)
    assert r["ratio_to_budget"] == pytest.approx(r["stereo_pair_ms"] / 33.0, abs=0.006)
    assert r["target_ms"] > 0 and r["shade_ms"] > 0 and r["first_call_s"] > 0 and "splat" in r["counts"]
    # not on a terminal: the progress display's one summary line on stderr, after the stages
    assert re.search(r"^bench render: 4 of 4 stages in \d+\.\d s", res.stderr, re.M), res.stderr


def test_demo_section_has_every_camera_and_a_strip(take: Path, our_depth: Path, tmp_path: Path) -> None:
    from rigctl.render.demo import novel_views_section

    lines = novel_views_section(take, our_depth, tmp_path, (0, 15, 0, 110), steps=3)
    rows = [line for line in lines if line.startswith("| r")]
    assert len(rows) == 9 and "true disparity" in lines[4] and "our depth" in lines[4]
    strip = cv2.imread(str(tmp_path / "novel-views.png"))
    assert strip.shape == (180, 3 * 320, 3)


def test_frames_without_disparity_are_left_out_by_default_and_refused_when_asked_for(tmp_path: Path) -> None:
    """A depth run over part of a take (rigctl depth --frames 0-0) once made a default render write frame 0
    and then fail on frame 1: by default the frames the disparity folder has are rendered (with a warning
    naming them), and asked-for frames without a disparity are refused before anything is written."""
    res = run_rigctl(
        "record", "--take", "two", "--frames", "2", "--out", str(tmp_path),
        "--sim", "ideal=true", "--sim", "motion=false", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    take = tmp_path / "two"
    part = tmp_path / "part"
    shutil.copytree(take / "truth" / "disparity" / "000000", part / "000000")
    out = tmp_path / "out"
    res = run_rigctl("render", str(take), "--disparity", str(part), "--at", "1,1", "--out", str(out), "--json")
    assert res.returncode == 0, res.stderr
    assert [v["frame"] for v in json.loads(res.stdout)["views"]] == ["000000"]
    assert "disparities for 1 of the 2 complete frame sets" in res.stderr and "rendering those (0)" in res.stderr
    out2 = tmp_path / "out2"
    res = run_rigctl(
        "render", str(take), "--disparity", str(part), "--at", "1,1", "--frames", "0-1", "--out", str(out2)
    )
    one_line(res, "no disparity for frame 1")
    assert not list(out2.rglob("*.png"))


def test_a_disparity_made_from_another_take_is_named_in_a_warning(take: Path, tmp_path: Path) -> None:
    """A depth output of another take renders wrong views without an error: its report.json says where it
    came from, and a take's own truth folder says so by where it is."""
    truth = take / "truth" / "disparity"
    res = run_rigctl("render", str(take), "--disparity", str(truth), "--at", "1,1", "--out", str(tmp_path / "a"))
    assert res.returncode == 0 and "was made from" not in res.stderr, res.stderr
    other = tmp_path / "other-depth"
    shutil.copytree(truth, other)
    (other / "report.json").write_text(json.dumps({"source": str(tmp_path / "far-take"), "frames": {}}))
    res = run_rigctl("render", str(take), "--disparity", str(other), "--at", "1,1", "--out", str(tmp_path / "b"))
    assert res.returncode == 0
    assert f"{other} was made from {tmp_path / 'far-take'}, not from {take}" in res.stderr, res.stderr


def test_bench_render_refuses_a_size_the_memory_cannot_hold() -> None:
    """16384x16384 once ended in OpenCV's out-of-memory traceback (or took the machine's memory). The memory
    available is given, not read from this machine."""
    from rigctl.cli.render import check_bench_memory
    from rigctl.errors import ParameterError

    with pytest.raises(ParameterError, match=r"--size 16384x16384: needs about 80\.5 GB .* 24\.0 GB available"):
        check_bench_memory((16384, 16384), 24 << 30)
    check_bench_memory((1920, 1080), 24 << 30)  # the default fits
    check_bench_memory((16384, 16384), None)  # no figure, no check


def test_a_frame_with_no_estimate_in_any_disparity_is_refused_before_writing(take: Path, tmp_path: Path) -> None:
    """Every disparity +inf (no estimate) once rendered fully transparent views with exit 0 and a warning, and
    leave-one-out scored them (7 dB) without one: refused in one line naming the folder and the frame, exit 3."""
    from rigctl.pfm import read_pfm, write_pfm

    truth = take / "truth" / "disparity"
    none, only = tmp_path / "none", tmp_path / "only-r1c1"
    for pfm in sorted(truth.rglob("*.pfm")):
        for folder in (none, only):
            d = read_pfm(pfm)
            keep = folder == only and pfm.stem == "r1c1"
            write_pfm(folder / pfm.relative_to(truth), d if keep else np.full_like(d, np.inf))
    out = tmp_path / "views"
    res = run_rigctl("render", str(take), "--disparity", str(none), "--at", "1,1", "--frames", "0-0", "--out", str(out))
    assert res.returncode == 3, res.stderr
    one_line(res, str(none), "frame 0", "no camera's disparity holds an estimate")
    assert not out.exists()
    res = run_rigctl("render", str(take), "--disparity", str(none), "--leave-one-out", "--cameras", "r1c1", "--json")
    assert res.returncode == 3 and not res.stdout, (res.stdout, res.stderr)
    one_line(res, str(none), "frame 0", "no camera's disparity holds an estimate")
    res = run_rigctl("render", str(take), "--disparity", str(only), "--leave-one-out", "--cameras", "r1c1", "--json")
    assert res.returncode == 3 and not res.stdout, (res.stdout, res.stderr)
    one_line(res, str(only), "frame 0", "no camera but r1c1 has an estimate")
    res = run_rigctl("render", str(take), "--disparity", str(only), "--at", "1,1", "--out", str(out))
    assert res.returncode == 0, res.stderr  # r1c1's own estimate is a source of a view beside it


def test_a_path_render_the_disk_cannot_hold_is_refused_before_writing(
    take: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A review: render --path had no disk-space check, so a long path could fill the disk halfway through. The
    estimate (frames x views x resolution x PNG + EXR, as if uncompressed) is held against the free space of
    --out's file system up front; the free space is given here, not read from this disk."""
    import rigctl.diskspace
    from rigctl.cli.main import main
    from rigctl.errors import EXIT_DEVICE
    from rigctl.render.views import views_bytes

    asked: list[Path] = []

    def free(folder: Path) -> int:
        asked.append(folder)
        return given

    monkeypatch.setattr(rigctl.diskspace, "free_bytes", free)
    out = tmp_path / "new" / "path"
    argv = ["render", str(take), "--disparity", str(take / "truth" / "disparity"), "--path", "0,1", "2,1", "--out",
            str(out), "--quiet"]  # fmt: skip
    given = 10 * 10**6
    code = main([*argv, "--steps", "50"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_DEVICE and len(err) == 1, err
    assert f"--out {out}: about 0.34 GB needed for 50 views of 960x540 (PNG + EXR), 0.01 GB free" in err[0]
    assert asked == [out] and not (tmp_path / "new").exists()  # refused before a view: the folder made is gone

    given = views_bytes(3, 960, 540)  # just enough: it renders, and what it wrote fits the estimate
    assert main([*argv, "--steps", "3"]) == 0, capsys.readouterr().err
    written = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    assert sorted(p.name for p in (out / "000000").glob("*.exr")) == [f"path_000{i}.exr" for i in range(3)]
    assert 0 < written <= given
