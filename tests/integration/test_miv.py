"""MIV content out and in on simulated presenter takes (two frame sets, true disparity, so the
figures measure the interchange and the renderers, not our depth): the export read back (geometry, colour,
depth), rigctl render on the imported content against the original take, MPEG's RVS (built from its source)
on our export against rigctl render and against the simulator's view, and the refusals."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from interop_support import reference_tool
from tests_support import run_rigctl

from rigctl import registry
from rigctl.depth.grid import TakeGrid
from rigctl.interop import yuv
from rigctl.interop.ivpsnr import upsample_420
from rigctl.interop.miv import depth_name, texture_name
from rigctl.interop.miv_import import read_content
from rigctl.keying import Keyer
from rigctl.pfm import read_pfm
from rigctl.render.score import score

W, H = 960, 540
AT = (1.5, 1.0)  # between r1c1 and r1c2


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    """An ideal simulated take: the simulator's view between cameras is exactly what it should show."""
    out = module_tmp("miv")
    res = run_rigctl(
        "record", "--take", "ideal", "--frames", "2", "--out", str(out),
        "--sim", "ideal=true", "--sim", "motion=false", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return out / "ideal"


@pytest.fixture(scope="module")
def rectified(take: Path) -> Path:
    """A simulated presenter take (mounting errors, focal spread, distortion) rectified with its true
    calibration: the cameras off the lattice by up to half a millimetre, the principal point off centre."""
    out = take.parent
    res = run_rigctl("record", "--take", "real", "--frames", "2", "--out", str(out), "--sim", "motion=false", "--force")
    assert res.returncode == 0, res.stderr
    cal = out / "real" / "truth" / "calibration.yaml"
    res = run_rigctl("rectify", str(out / "real"), "--calibration", str(cal), "--out", str(out / "rectified"))
    assert res.returncode == 0, res.stderr
    return out / "rectified"


@pytest.fixture(scope="module")
def rectified_content(rectified: Path) -> Path:
    out = rectified.parent / "rectified-content"
    res = run_rigctl("miv", "export", str(rectified), str(rectified / "truth" / "disparity"), "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def content(take: Path) -> Path:
    out = take.parent / "content"
    res = run_rigctl("miv", "export", str(take), str(take / "truth" / "disparity"), "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def imported(content: Path) -> Path:
    out = content.parent / "imported"
    res = run_rigctl("miv", "import", str(content / "cameras.json"), "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out


def rgb_of_png(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return img[..., 2::-1].astype(np.float32) / 255.0


def truth(take: Path) -> tuple[np.ndarray, np.ndarray, tuple[int, int, int, int] | None]:
    rgb, _subject = registry.simulated_view(take, *AT)
    return rgb, Keyer().matte(rgb), registry.simulated_burnin_box(take, W)


def test_the_export_names_every_file_and_reads_back_to_the_same_geometry(
    rectified: Path, rectified_content: Path
) -> None:
    take, content = rectified, rectified_content
    readme = (content / "README.txt").read_text()
    files = sorted(p.name for p in content.iterdir() if p.name != "README.txt")
    assert len(files) == 1 + 2 * 9
    assert all(f"{f}:" in readme for f in files)  # a line per file
    rect = TakeGrid(take).reader.manifest.rectification
    assert rect is not None
    got = read_content(content / "cameras.json")
    centres = np.array(list(rect.positions_m.values()))
    mean = centres.mean(axis=0)
    assert {c.grid_name for c in got.cameras} == set(rect.positions_m)
    for cam in got.cameras:
        assert cam.grid_name == cam.name
        assert np.abs(cam.position_cv - (np.array(rect.positions_m[cam.name]) - mean)).max() < 1e-6
    assert abs(got.focal_px - rect.focal_px) < 1e-6
    assert abs(got.principal_cv[0] - rect.K[0][2]) < 1e-6 and abs(got.principal_cv[1] - rect.K[1][2]) < 1e-6
    assert abs(got.spacing_x - rect.spacing_x_m) < 1e-9 and abs(got.spacing_y - rect.spacing_y_m) < 1e-9
    assert rect.lattice_residual_mm > 0.1  # a real rectified take: not on an exact lattice
    assert got.frame_count() == 2


def test_the_export_reads_back_to_the_same_pixels_and_depth(rectified: Path, rectified_content: Path) -> None:
    take, content = rectified, rectified_content
    got = read_content(content / "cameras.json")
    grid = TakeGrid(take).grid(1)
    near, far = got.cameras[0].depth_range
    step = (1 / near - 1 / far) / 65535  # one 16-bit level of inverse depth
    for cam in got.cameras:
        exact = np.stack(yuv_exact(grid.images[cam.name]))
        y, cb, cr = got.colour(cam, 1)
        assert np.abs(y - exact[0]).max() <= 0.5 + 1e-6  # 10-bit rounding
        for plane, full in ((cb, exact[1]), (cr, exact[2])):
            block = full.reshape(H // 2, 2, W // 2, 2).mean(axis=(1, 3))
            assert np.abs(plane - block).max() <= 0.5 + 1e-6  # 4:2:0 of the same picture, rounded once
        d0 = read_pfm(take / "truth" / "disparity" / "000001" / f"{cam.name}.pfm")
        d1 = got.disparity(cam, 1)
        assert np.array_equal(np.isinf(d0), np.isinf(d1))
        fin = np.isfinite(d0)
        inv0 = d0[fin].astype(np.float64) / (got.focal_px * got.spacing_x)
        inv1 = d1[fin].astype(np.float64) / (got.focal_px * got.spacing_x)
        assert np.abs(inv1 - inv0).max() <= 0.5 * step * 1.04  # and the float32 rounding of a PFM


def yuv_exact(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """BT.709 limited-range YCbCr at 10 bits, unrounded."""
    r, g, b = (rgb[..., i].astype(np.float64) for i in range(3))
    y = 0.2126 * r + 0.7152 * g + 0.0722 * b
    return 4 * (16 + 219 * y), 4 * (128 + 224 * (b - y) / 1.8556), 4 * (128 + 224 * (r - y) / 1.5748)


def test_render_on_the_imported_content_reproduces_render_on_the_take(take: Path, imported: Path) -> None:
    views = {}
    for name, src, disp in (
        ("take", take, take / "truth" / "disparity"),
        ("imported", imported / "000001", imported / "000001" / "truth"),
    ):
        out = take.parent / f"view-{name}"
        res = run_rigctl("render", str(src), "--disparity", str(disp), "--at", f"{AT[0]},{AT[1]}", "--out", str(out))
        assert res.returncode == 0, res.stderr
        frame = "000001" if name == "take" else "000000"
        views[name] = rgb_of_png(out / frame / "c1.5r1.png")
    rgb, alpha, box = truth(take)
    s_take = score(views["take"], rgb, alpha, box)
    s_imp = score(views["imported"], rgb, alpha, box)
    y_take, y_imp = (luma_psnr(views[k], rgb, alpha, box) for k in ("take", "imported"))
    print(f"against the simulator's view: take {s_take}, Y {y_take:.2f} dB; imported {s_imp}, Y {y_imp:.2f} dB")
    assert s_take["psnr_db"] > 35
    # the geometry and the luma survive the round trip: the views agree in Y; the 4:2:0 chroma of MIV
    # content costs the colourful presenter about 2.4 dB of RGB PSNR (41 dB per source picture), stated
    assert abs(y_take - y_imp) <= 0.5, (y_take, y_imp)
    assert s_imp["psnr_db"] > s_take["psnr_db"] - 3.0, (s_take, s_imp)


def luma_psnr(
    view: np.ndarray, reference: np.ndarray, alpha: np.ndarray, box: tuple[int, int, int, int] | None
) -> float:
    """PSNR (dB) of the 10-bit BT.709 luma on the keyed subject, the burn-in left out."""
    mask = alpha > 0.5
    if box is not None:
        mask[box[0] : box[1], box[2] : box[3]] = False
    a, b = (yuv.rgb_to_ycbcr(v, 10)[0].astype(np.float64) for v in (view, reference))
    return float(10 * np.log10(1023**2 / np.mean((a[mask] - b[mask]) ** 2)))


def rvs_view(content: Path, work: Path, sources: list[str], cameras_json: Path | None = None) -> np.ndarray:
    """RVS's view at ``AT`` from ``sources`` of the content (cameras from ``cameras_json``, default the
    content's own), as R'G'B' float."""
    doc = json.loads((cameras_json or content / "cameras.json").read_text())
    cams = {c["Name"]: c for c in doc["cameras"]}
    virtual = dict(cams["r1c1"], Name="v")
    virtual["Position"] = [(a + b) / 2 for a, b in zip(cams["r1c1"]["Position"], cams["r1c2"]["Position"], strict=True)]
    work.mkdir(parents=True, exist_ok=True)
    (work / "virtual.json").write_text(json.dumps({"Version": "4.0", "cameras": [virtual]}))
    (work / "inputs.json").write_text(json.dumps(doc))
    config = {
        "Version": "3.0",
        "InputCameraParameterFile": "inputs.json",
        "VirtualCameraParameterFile": "virtual.json",
        "InputCameraNames": sources,
        "VirtualCameraNames": ["v"],
        "ViewImageNames": [str(content / texture_name(n, W, H)) for n in sources],
        "DepthMapNames": [str(content / depth_name(n, W, H)) for n in sources],
        "OutputFiles": ["v.yuv"],
        "StartFrame": 1,
        "NumberOfFrames": 1,
        "Precision": 1.0,
        "ColorSpace": "YUV",
        "ViewSynthesisMethod": "Triangles",
        "BlendingMethod": "Simple",
        "BlendingFactor": 5.0,
    }
    (work / "rvs.json").write_text(json.dumps(config))
    proc = subprocess.run(
        [str(reference_tool("rvs")), "rvs.json"], cwd=work, capture_output=True, text=True, timeout=300
    )  # RVS resolves relative paths from the current folder
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    planes = yuv.read_frame(work / "v.yuv", W, H, 10)
    return yuv.ycbcr_to_rgb(upsample_420(*planes), 10)  # type: ignore[arg-type]


def test_rvs_on_our_export_agrees_with_rigctl_render(take: Path, content: Path) -> None:
    out = take.parent / "view-rvs-ours"
    res = run_rigctl(
        "render", str(take), "--disparity", str(take / "truth" / "disparity"), "--at", f"{AT[0]},{AT[1]}",
        "--frames", "1-1", "--out", str(out), "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    sources = json.loads(res.stdout)["views"][0]["sources"]
    ours = rgb_of_png(out / "000001" / "c1.5r1.png")
    rvs = rvs_view(content, take.parent / "rvs", sources)
    rgb, alpha, box = truth(take)
    s_rvs, s_ours, s_both = score(rvs, rgb, alpha, box), score(ours, rgb, alpha, box), score(rvs, ours, alpha, box)
    print(f"RVS vs truth {s_rvs}; rigctl render vs truth {s_ours}; RVS vs rigctl render {s_both}")
    assert s_both["psnr_db"] >= 35.0, s_both  # the two renderers agree on the keyed subject
    assert s_rvs["psnr_db"] >= 34.0 and s_ours["psnr_db"] >= 35.0, (s_rvs, s_ours)
    # the check can fail: a camera file with the horizontal axis mirrored (y right instead of left)
    doc = json.loads((content / "cameras.json").read_text())
    for c in doc["cameras"]:
        c["Position"][1] = -c["Position"][1]
    mirrored = take.parent / "mirrored.json"
    mirrored.write_text(json.dumps(doc))
    wrong = rvs_view(content, take.parent / "rvs-mirrored", sources, mirrored)
    assert score(wrong, rgb, alpha, box)["psnr_db"] < s_rvs["psnr_db"] - 8


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda cams: cams[4]["Position"].__setitem__(0, 0.2), "r1c1 is 200.0 mm in front of or behind"),
        (lambda cams: cams[3]["Focal"].__setitem__(0, 1000.0), "Focal"),
        (lambda cams: cams[2].__setitem__("Projection", "Equirectangular"), "only perspective"),
        (lambda cams: cams[5]["Position"].__setitem__(1, 0.03), "off the grid's column lattice"),
    ],
)
def test_content_that_is_not_a_planar_grid_is_refused_in_one_line(
    content: Path, tmp_path: Path, change, message
) -> None:
    doc = json.loads((content / "cameras.json").read_text())
    cams = sorted(doc["cameras"], key=lambda c: c["Name"])
    change(cams)
    bad = tmp_path / "cameras.json"
    bad.write_text(json.dumps({"Version": "4.0", "cameras": cams}))
    res = run_rigctl("miv", "import", str(bad), "--out", str(tmp_path / "out"))
    assert res.returncode == 3, res.stderr
    assert res.stderr.count("\n") == 1 and message in res.stderr, res.stderr
    assert not (tmp_path / "out").exists()


def test_export_into_an_existing_folder_is_refused(take: Path, content: Path) -> None:
    res = run_rigctl("miv", "export", str(take), str(take / "truth" / "disparity"), "--out", str(content))
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "already exists" in res.stderr


def test_export_reads_a_depth_output_without_pfms_from_its_exrs(take: Path, content: Path, tmp_path: Path) -> None:
    """Depth outputs hold the PFM only when asked (``--formats``, issue 24): each camera's disparity is read
    from its EXR's NUKE layers, and the content is the same, byte for byte, as from the PFMs."""
    from rigctl.disparity_layers import header, layers, steps
    from rigctl.exr import write_exr

    exrs = tmp_path / "exr-only"
    offsets = TakeGrid(take).offsets
    for pfm in sorted((take / "truth" / "disparity").glob("*/*.pfm")):
        d = read_pfm(pfm)
        (exrs / pfm.parent.name).mkdir(parents=True, exist_ok=True)
        z = np.where(np.isfinite(d), np.float32(1.0), np.float32(0.0))  # 0 where there is none, as depth writes
        st = steps(offsets, pfm.stem)
        write_exr(exrs / pfm.parent.name / f"{pfm.stem}.exr", {"depth.Z": z, **layers(d, st)}, header(st))
    assert not list(exrs.rglob("*.pfm"))
    res = run_rigctl("miv", "export", str(take), str(exrs), "--out", str(tmp_path / "miv"))
    assert res.returncode == 0, res.stderr
    ours = sorted(p.relative_to(tmp_path / "miv") for p in (tmp_path / "miv").rglob("*") if p.is_file())
    assert ours == sorted(p.relative_to(content) for p in content.rglob("*") if p.is_file())
    for rel in ours:  # README.txt names the folder the disparities came from
        if rel.name != "README.txt":
            assert (tmp_path / "miv" / rel).read_bytes() == (content / rel).read_bytes(), rel


@pytest.mark.parametrize(
    ("value", "message"), [(np.nan, "holds NaN"), (3e38, "beyond the image's width"), (-3e38, "beyond the image")]
)
def test_export_refuses_a_disparity_render_would_refuse(take: Path, tmp_path: Path, value: float, message: str) -> None:
    """A disparity from others that no camera could have seen (NaN, 3e38) is one line naming the file, as in
    ``rigctl render``: it was coded into depth levels as if it were the nearest point."""
    from rigctl.pfm import write_pfm

    bad = tmp_path / "disparity"
    shutil.copytree(take / "truth" / "disparity", bad)
    victim = sorted(bad.glob("*/r1c1.pfm"))[0]
    d = read_pfm(victim)
    d[d.shape[0] // 2, d.shape[1] // 3] = value
    write_pfm(victim, d)
    res = run_rigctl("miv", "export", str(take), str(bad), "--out", str(tmp_path / "miv"))
    assert res.returncode == 3 and res.stderr.count("\n") == 1, res.stderr
    assert str(victim) in res.stderr and message in res.stderr and not (tmp_path / "miv").exists()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{", "not JSON"),
        ("[" * 100000, "nested too deep"),  # Python's parser gave up with a RecursionError
        ('{"cameras": 3}', 'no "cameras" list'),
        ('{"cameras": [{"Name": "v0", "Resolution": [0, 0]}]}', "Resolution [0, 0]"),
        ('{"cameras": [{"Name": "v0", "Resolution": [64, 48], "Focal": ["a", 1]}]}', "Focal must be 2 finite numbers"),
    ],
)
def test_a_hostile_camera_file_is_refused_in_one_line(tmp_path: Path, text: str, message: str) -> None:
    bad = tmp_path / "cameras.json"
    bad.write_text(text)
    res = run_rigctl("miv", "import", str(bad), "--out", str(tmp_path / "out"))
    assert res.returncode == 3 and res.stderr.count("\n") == 1 and message in res.stderr, res.stderr


def test_content_with_a_missing_or_short_file_is_refused_in_one_line(content: Path, tmp_path: Path) -> None:
    folder = tmp_path / "content"
    shutil.copytree(content, folder)
    (folder / texture_name("r2c2", W, H)).unlink()
    res = run_rigctl("miv", "import", str(folder / "cameras.json"), "--out", str(tmp_path / "a"))
    assert res.returncode == 3 and res.stderr.count("\n") == 1 and "r2c2_texture" in res.stderr, res.stderr
    shutil.copytree(content, folder, dirs_exist_ok=True)
    with open(folder / depth_name("r1c1", W, H), "r+b") as f:
        f.truncate(1000)
    res = run_rigctl("miv", "import", str(folder / "cameras.json"), "--out", str(tmp_path / "b"))
    assert res.returncode == 3 and res.stderr.count("\n") == 1 and "r1c1_depth" in res.stderr, res.stderr
    assert not (tmp_path / "b").exists()  # checked before anything is written


@pytest.mark.parametrize("kind", ["dev_zero", "fifo", "empty"])
def test_content_whose_picture_is_no_regular_file_or_empty_is_refused_not_imported_as_nothing(
    content: Path, tmp_path: Path, kind: str
) -> None:
    """A texture swapped for /dev/zero (no size, never ends) or an empty file gave "wrote 0 grid folder(s)" and
    exit 0; a FIFO is refused before a read blocks on it (a hostile-user review)."""
    folder = tmp_path / "content"
    shutil.copytree(content, folder)
    victim = folder / texture_name("r1c1", W, H)
    victim.unlink()
    if kind == "dev_zero":
        victim.symlink_to("/dev/zero")
    elif kind == "fifo":
        os.mkfifo(victim)
    else:
        victim.write_bytes(b"")
    res = run_rigctl("miv", "import", str(folder / "cameras.json"), "--out", str(tmp_path / "out"), timeout=60)
    assert res.returncode == 3 and res.stderr.count("\n") == 1 and "r1c1_texture" in res.stderr, res.stderr
    assert ("empty" if kind == "empty" else "not a regular file") in res.stderr
    assert not (tmp_path / "out").exists()


def test_depth_on_imported_content_scores_against_the_content_s_own_depth(imported: Path, tmp_path: Path) -> None:
    res = run_rigctl("depth", str(imported / "000000"), "--out", str(tmp_path / "d"), "--cameras", "r1c1", "--json")
    assert res.returncode == 0, res.stderr
    frames = json.loads(res.stdout)["frames"]
    scores = next(iter(frames.values()))["cameras"]["r1c1"]["against_truth"]
    assert scores["bad_2.0"] < 10, scores  # our depth on MIV content, scored against the depth it came with
