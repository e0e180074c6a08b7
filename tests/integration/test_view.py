"""rigctl view in a real headless Chromium (software WebGL): the page's views against rigctl render --at and
its leave-one-out score, parallax when the eye moves, playback of a 25-frame take that never mixes frame sets,
the server's paths, address and Ctrl-C, and bad input."""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from tests_support import run_rigctl

from rigctl.viewer.browser import Probe, done_info
from rigctl.viewer.bundle import Bundles
from rigctl.viewer.server import ViewerServer

REPO = Path(__file__).resolve().parents[2]
FRAMES = 25
POSITIONS = ("1,1", "1.5,1", "0.4,0.6")


def record(out: Path, frames: int, *sim: str) -> Path:
    """An ideal simulated presenter at 320x180 (already rectified, with its true disparity), the same bytes on
    every run."""
    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", "width_px: 320").replace("height_px: 540", "height_px: 180")
    (out / "small.yaml").write_text(rig)
    extra = [a for s in sim for a in ("--sim", s)]
    res = run_rigctl(
        "record", str(out / "small.yaml"), "--take", "t", "--frames", str(frames), "--out", str(out),
        "--sim", "ideal=true", "--sim", "deterministic=true", *extra, "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return out / "t"


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    """One still frame set (rigctl render scores views against the simulator's only on still takes)."""
    return record(module_tmp("view"), 1, "motion=false")


@pytest.fixture(scope="module")
def server(take: Path) -> Iterator[ViewerServer]:
    srv = ViewerServer(Bundles(take, take / "truth" / "disparity"), accept_results=True)
    srv.start()
    yield srv
    srv.shutdown()
    srv.server_close()


@pytest.fixture(scope="module")
def shots(server: ViewerServer) -> dict[str, np.ndarray]:
    """The page's views of frame set 0 at POSITIONS and r1c1 left out, as it read them back (RGBA8)."""
    with Probe(server, probe="shots", frame="0", at=";".join(POSITIONS), loo="r1c1", stereo="1,1", ipd="60",
               keys=",".join(["ArrowRight"] * 5 + ["ArrowUp"] * 3 + ["ArrowDown"] * 3)) as probe:  # fmt: skip
        got = probe.collect()
    assert done_info(got)["gl"]  # the page names the GL implementation it ran on
    h, w = server.bundles.height, server.bundles.width
    pictures = ("at:", "loo:", "eye:", "keys:")
    views = {t: np.frombuffer(b, np.uint8).reshape(h, w, 4) for t, b in got.items() if t.startswith(pictures)}
    sources = {t[8:]: json.loads(b) for t, b in got.items() if t.startswith("sources:")}
    return views | {"keys": json.loads(got["keys"]), "limit": json.loads(got["limit"]), "sources": sources}  # type: ignore[dict-item]


def psnr_keyed(cpu: np.ndarray, gpu: np.ndarray) -> float:
    """PSNR of the RGB on the CPU view's keyed subject (alpha > 0)."""
    key = cpu[..., 3] > 0
    mse = float(((cpu[..., :3].astype(float) - gpu[..., :3].astype(float)) ** 2)[key].mean())
    return 10 * np.log10(255**2 / max(mse, 1e-10))


def test_the_page_renders_what_rigctl_render_writes_at_three_positions(
    take: Path, shots: dict[str, np.ndarray], tmp_path: Path
) -> None:
    args = [a for p in POSITIONS for a in ("--at", p)]
    res = run_rigctl(
        "render", str(take), "--disparity", str(take / "truth" / "disparity"), *args, "--frames", "0-0",
        "--out", str(tmp_path), "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    views = {v["view"]: v for v in json.loads(res.stdout)["views"]}
    figures = {}
    for p in POSITIONS:
        col, row = (float(x) for x in p.split(","))
        stem = f"c{col:g}r{row:g}"
        png = cv2.imread(str(tmp_path / "000000" / f"{stem}.png"), cv2.IMREAD_UNCHANGED)
        cpu = cv2.cvtColor(png, cv2.COLOR_BGRA2RGBA)
        gpu = shots[f"at:{p}"]
        assert (cpu[..., 3] > 0).mean() > 0.1, "the CPU view shows the subject"
        assert (gpu[..., 3] > 0).sum() > 0.9 * (cpu[..., 3] > 0).sum(), "the page's view shows the subject"
        assert shots["sources"][p] == views[stem]["sources"]  # the same four nearest cameras
        figures[p] = psnr_keyed(cpu, gpu)
        assert np.abs(cpu[..., 3].astype(int) - gpu[..., 3]).mean() < 1.0  # the same key
    print("PSNR of the page against rigctl render --at, keyed subject:", figures)
    assert min(figures.values()) >= 35.0, figures


def test_leave_one_out_through_the_page_scores_as_the_cpu_renderer(take: Path, shots: dict[str, np.ndarray]) -> None:
    from rigctl.cli.render import simulator_hooks
    from rigctl.render.inputs import RenderInput
    from rigctl.render.score import score

    res = run_rigctl(
        "render", str(take), "--disparity", str(take / "truth" / "disparity"), "--leave-one-out", "--cameras",
        "r1c1", "--frames", "0-0", "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    cpu = json.loads(res.stdout)["leave_one_out"][0]
    view = RenderInput(take, take / "truth" / "disparity").frame(0).views["r1c1"]
    box = simulator_hooks(take, view.rgb.shape[1])[1]
    gpu = shots["loo:r1c1"][..., :3].astype(np.float32) / 255
    got = score(gpu, view.rgb, view.alpha, box)
    print(f"leave-one-out r1c1: page {got['psnr_db']:.3f} dB, CPU {cpu['psnr_db']:.3f} dB")
    assert "r1c1" not in shots["sources"]["r1c1"] and shots["sources"]["r1c1"] == cpu["sources"]
    assert abs(got["psnr_db"] - cpu["psnr_db"]) <= 1.0, (got, cpu)
    # and it can fail: the same view one pixel off scores far worse
    shifted = score(np.roll(gpu, 2, axis=1), view.rgb, view.alpha, box)
    assert shifted["psnr_db"] < cpu["psnr_db"] - 1.0


def test_the_pages_stereo_pair_is_rigctl_renders(take: Path, shots: dict[str, np.ndarray], tmp_path: Path) -> None:
    res = run_rigctl(
        "render", str(take), "--disparity", str(take / "truth" / "disparity"), "--at", "1,1", "--stereo", "0.06",
        "--out", str(tmp_path),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    figures = {}
    for eye in "LR":
        png = cv2.imread(str(tmp_path / "000000" / f"c1r1_{eye}.png"), cv2.IMREAD_UNCHANGED)
        figures[eye] = psnr_keyed(cv2.cvtColor(png, cv2.COLOR_BGRA2RGBA), shots[f"eye:{eye}"])
    print("the page's eye pair (IPD 60 mm) against rigctl render --stereo 0.06:", figures)
    assert min(figures.values()) >= 35.0, figures
    assert np.abs(shots["eye:L"].astype(int) - shots["eye:R"]).mean() > 1.0  # two different eyes


def test_our_depth_serves_and_matches_too(take: Path, tmp_path: Path) -> None:
    """rigctl depth's output (as the demo makes it), not only the simulator's truth."""
    depth = tmp_path / "depth"
    res = run_rigctl("depth", str(take), "--out", str(depth), "--near", "1.95", "--far", "3.0")
    assert res.returncode == 0, res.stderr
    res = run_rigctl("render", str(take), "--disparity", str(depth), "--at", "1.25,1", "--out", str(tmp_path / "v"))
    assert res.returncode == 0, res.stderr
    srv = ViewerServer(Bundles(take, depth), accept_results=True)
    srv.start()
    try:
        with Probe(srv, probe="shots", frame="0", at="1.25,1") as probe:
            got = probe.collect()
    finally:
        srv.shutdown()
        srv.server_close()
    gpu = np.frombuffer(got["at:1.25,1"], np.uint8).reshape(srv.bundles.height, srv.bundles.width, 4)
    png = cv2.imread(str(tmp_path / "v" / "000000" / "c1.25r1.png"), cv2.IMREAD_UNCHANGED)
    cpu = cv2.cvtColor(png, cv2.COLOR_BGRA2RGBA)
    assert (gpu[..., 3] == 255).sum() > 2000  # the keyed subject is there
    figure = psnr_keyed(cpu, gpu)
    print(f"our depth, view at 1.25,1: the page against rigctl render --at: {figure:.1f} dB")
    assert figure >= 35.0


def test_the_arrow_keys_move_the_eye(shots: dict[str, np.ndarray]) -> None:
    """Five presses of the right arrow from 1,1 (and three up, three down): the view at 1.5,1."""
    place = shots["keys"]
    assert place["col"] == pytest.approx(1.5) and place["row"] == pytest.approx(1.0), place
    assert psnr_keyed(shots["at:1.5,1"], shots["keys:view"]) >= 35.0
    # forty more: the eye stops where rigctl render --at stops, one spacing beyond the cameras, and says so
    limit = shots["limit"]
    assert limit["col"] == 3.0 and "columns -1..3" in limit["shown"], limit


def best_shift(ref: np.ndarray, moved: np.ndarray, mask: np.ndarray) -> int:
    """The leftward shift (pixels) that best maps ``ref``'s pixels in ``mask`` onto ``moved``."""
    ys, xs = np.nonzero(mask)
    errs = []
    for s in range(0, 40):
        ok = xs - s >= 0
        errs.append(np.abs(ref[ys[ok], xs[ok], :3].astype(int) - moved[ys[ok], xs[ok] - s, :3]).mean())
    return int(np.argmin(errs))


def test_moving_the_eye_moves_the_hands_more_than_the_torso(take: Path, shots: dict[str, np.ndarray]) -> None:
    from rigctl.pfm import read_pfm

    centre, right = shots["at:1,1"], shots["at:1.5,1"]
    assert (centre[..., 3] > 0).sum() > 2000  # the subject is on screen
    assert np.abs(centre.astype(int) - right).mean() > 1.0  # the picture changes
    d = read_pfm(take / "truth" / "disparity" / "000000" / "r1c1.pfm")
    subject = np.isfinite(d) & (centre[..., 3] == 255)
    near = subject & (d >= np.percentile(d[subject], 97))  # the hands reaching forward
    torso = subject & (np.abs(d - np.percentile(d[subject], 40)) < 0.5)
    s_near, s_torso = best_shift(centre, right, near), best_shift(centre, right, torso)
    print(f"half a spacing to the right: hands move {s_near} px, torso {s_torso} px")
    assert s_near >= s_torso + 2, (s_near, s_torso)


@pytest.fixture(scope="module")
def moving(module_tmp: Callable[[str], Path]) -> Path:
    """25 frame sets of the presenter in motion from the first frame."""
    return record(module_tmp("view-moving"), FRAMES, "motion_ramp_s=0")


def test_a_bundle_holds_one_frame_sets_colour_and_disparity(moving: Path) -> None:
    from rigctl.render.inputs import RenderInput
    from rigctl.viewer.bundle import MAGIC

    bundles = Bundles(moving, moving / "truth" / "disparity")
    assert bundles.numbers == list(range(FRAMES))
    inp = RenderInput(moving, moving / "truth" / "disparity")
    h, w = bundles.height, bundles.width
    for n in (3, 17):
        data = bundles.get(n)
        assert data[:4] == MAGIC
        size = int.from_bytes(data[4:8], "little")
        header = json.loads(data[8 : 8 + size])
        assert header["number"] == n
        at = 8 + size + header["cameras"].index("r1c1") * h * w * 8
        colour = np.frombuffer(data, np.uint8, h * w * 4, at).reshape(h, w, 4)
        disp = np.frombuffer(data, "<f4", h * w, at + h * w * 4).reshape(h, w)
        view = inp.frame(n).views["r1c1"]
        assert np.array_equal(colour[..., :3], np.clip(view.rgb * 255 + 0.5, 0, 255).astype(np.uint8))
        assert view.disparity is not None
        assert np.array_equal(np.isfinite(view.disparity), disp > -1e5)
        assert np.array_equal(disp[disp > -1e5], view.disparity[np.isfinite(view.disparity)])
    assert not np.array_equal(bundles.get(3)[8 + size :], bundles.get(17)[8 + size :])  # the subject moves


def test_playback_shows_each_frame_set_whole_and_in_order(moving: Path) -> None:
    srv = ViewerServer(Bundles(moving, moving / "truth" / "disparity"), accept_results=True)
    srv.start()
    try:
        with Probe(srv, probe="play") as probe:
            played = json.loads(probe.collect()["play"])
    finally:
        srv.shutdown()
        srv.server_close()
    shown = played["shown"]
    numbers = [s["number"] for s in shown]
    assert numbers[0] == 0 and numbers[-1] == FRAMES - 1, numbers
    assert all(b > a for a, b in itertools.pairwise(numbers)), numbers  # forwards, each at most once
    for s in shown:  # every source's colour and disparity came from the frame set shown
        assert len(s["colour"]) == 9 and set(s["colour"]) == set(s["disparity"]) == {s["number"]}, s
    seconds = (shown[-1]["t"] - shown[0]["t"]) / 1000
    print(
        f"played {len(numbers)} of {FRAMES} frame sets in {seconds:.2f} s (the take lasts {FRAMES / 25:.2f} s), "
        f"{played['stalls']} waits for a frame set"
    )
