"""``rigctl process`` on real Dask clusters: a LocalCluster of worker processes, and a scheduler with two
workers started as real ``dask`` subprocesses on 127.0.0.1, one of them killed mid-run. Small simulated takes
(480x270, the fast preset on two cameras) keep each frame set around a second."""

from __future__ import annotations

import filecmp
import importlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from tests_support import rigctl_exe, run_rigctl

from rigctl.depth.run import DepthOptions
from rigctl.errors import ParameterError
from rigctl.farm.frame import frame_name
from rigctl.farm.run import FarmOptions, Status, process_take

REPO = Path(__file__).resolve().parents[2]
CAMS = ("r1c1", "r1c0")
CHUNK = 2  # three chunks of the six frame sets: both workers get some
WARMUP = 2  # the last chunk warms up on two frame sets of the one before (not on the take's start)
FAST = ["--preset", "fast", "--cameras", *CAMS, "--chunk", str(CHUNK), "--warmup", str(WARMUP)]
FAST += ["--formats", "exr,pfm,png"]  # every output, so that each is compared between depth and process
FRAMES = 6


@pytest.fixture(scope="module")
def take(module_tmp: Callable[[str], Path]) -> Path:
    """An ideal simulated take (already rectified) at 480x270, six frame sets, every one of them whatever the
    machine's load (deterministic capture)."""
    out = module_tmp("farm")
    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", "width_px: 480").replace("height_px: 540", "height_px: 270")
    (out / "small.yaml").write_text(rig)
    res = run_rigctl(
        "record", str(out / "small.yaml"), "--take", "t", "--frames", str(FRAMES), "--out", str(out),
        "--sim", "ideal=true", "--sim", "deterministic=true", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return out / "t"


def written(out: Path, verb: str, *args: str) -> Path:
    """``out`` as ``rigctl VERB ... --out OUT`` wrote it (the run succeeded)."""
    res = run_rigctl(verb, *args, "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def single_process(take: Path, module_tmp: Callable[[str], Path]) -> Path:
    """What ``rigctl depth`` writes for the same frames in one process: the reference for byte identity."""
    return written(module_tmp("single"), "depth", str(take), *FAST)


def same_bytes(a: Path, b: Path) -> list[str]:
    """Files of ``a`` that are missing from ``b`` or differ from it byte for byte."""
    names = sorted(p.name for p in a.iterdir())
    _same, mismatch, errors = filecmp.cmpfiles(a, b, names, shallow=False)
    assert len(names) == 3 * len(CAMS)
    return mismatch + errors


def test_local_cluster_of_processes_matches_rigctl_depth_byte_for_byte(
    take: Path, single_process: Path, tmp_path: Path
) -> None:
    res = run_rigctl("process", str(take), "--out", str(tmp_path), "--workers", "2", *FAST, "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    rounds = summary["search"]["rounds"]  # 2 when a chunk widened the take's range: every chunk again from it
    assert summary["computed"] == FRAMES and summary["chunks"] == FRAMES // CHUNK  # each once
    assert summary["recomputed"] == (rounds - 1) * FRAMES  # the repeat passes, apart
    assert summary["chunks_recomputed"] == (rounds - 1) * FRAMES // CHUNK
    assert summary["failed"] == 0 and summary["search"]["settled"]
    ledger = json.loads((tmp_path / "process.json").read_text())
    report = json.loads((single_process / "report.json").read_text())
    assert ledger["range"] == report["range"] == summary["range"]  # decided once, the same way, for every chunk
    assert ledger["search"] == report["search"] == summary["search"]  # and settled the same way
    assert summary["bound_hit_pixels"] == report["bound_hit_pixels"]  # summed over the take alike
    frames = ledger["frames"]
    assert sorted(frames) == [frame_name(n) for n in range(FRAMES)]
    for name, entry in frames.items():
        assert entry["status"] == "done" and entry["worker"].startswith("tcp://127.0.0.1:") and entry["seconds"] > 0
        assert same_bytes(single_process / name, tmp_path / "depth" / name) == []
        assert sorted(entry["files"]) == sorted(p.name for p in (tmp_path / "depth" / name).iterdir())
        assert entry["report"]["disparity_range_px"] == report["frames"][str(int(name))]["disparity_range_px"]
    assert not list((tmp_path / "depth").glob(".partial-*"))


def test_a_rerun_after_an_interruption_computes_only_the_missing_frames(take: Path, tmp_path: Path) -> None:
    # a planned range: one round (a chunk that widened a measured range would have every chunk computed again)
    depth = DepthOptions(preset="fast", cameras=CAMS, chunk=CHUNK, warmup=WARMUP, disparity_range=(30.0, 60.0))
    opt = FarmOptions(take, tmp_path, depth, workers=1)

    def stop_after_two(st: Status) -> None:
        if st.done == 2:
            raise KeyboardInterrupt  # Ctrl-C on the client: the cluster goes down with it

    with pytest.raises(KeyboardInterrupt):
        process_take(opt, progress=stop_after_two)
    first = json.loads((tmp_path / "process.json").read_text())["frames"]
    assert len(first) == 2 and all(e["status"] == "done" for e in first.values())
    stamps = {name: (tmp_path / "depth" / name / "r1c1.exr").stat().st_mtime_ns for name in first}
    (tmp_path / "depth" / ".partial-000004-deadbeef").mkdir()  # what a write cut short leaves

    summary = process_take(opt)
    assert summary.skipped_done == 2 and summary.computed == FRAMES - 2 and summary.failed == 0
    ledger = json.loads((tmp_path / "process.json").read_text())["frames"]
    assert len(ledger) == FRAMES and all(e["status"] == "done" for e in ledger.values())
    assert {n: (tmp_path / "depth" / n / "r1c1.exr").stat().st_mtime_ns for n in first} == stamps
    assert not list((tmp_path / "depth").glob(".partial-*"))

    # a done frame whose file was damaged after the ledger recorded it (same size, other bytes): its chunk is
    # computed again, and the file is whole again
    damaged = tmp_path / "depth" / "000003" / "r1c0.exr"
    whole = damaged.read_bytes()
    damaged.write_bytes(whole[:-1] + bytes([whole[-1] ^ 0xFF]))
    fixed = process_take(opt)
    assert fixed.computed == CHUNK and fixed.skipped_done == FRAMES - CHUNK
    assert damaged.read_bytes() == whole

    again = process_take(FarmOptions(take, tmp_path, opt.depth, workers=1, frames=[0], redo=True))
    assert again.computed == 1 and again.skipped_done == 0
    assert not list((tmp_path / "depth").rglob("*.pfm")) and not list((tmp_path / "depth").rglob("r*.png"))

    # a frame set written without the PFM is not whole for a run that asks for it: computed again, with it
    pfm = process_take(FarmOptions(take, tmp_path, opt.depth, workers=1, frames=[0], formats=("exr", "pfm")))
    assert pfm.computed == 1 and pfm.skipped_done == 0
    assert sorted(p.name for p in (tmp_path / "depth" / "000000").iterdir()) == sorted(
        f"{c}.{e}" for c in CAMS for e in ("exr", "pfm")
    )
    assert process_take(FarmOptions(take, tmp_path, opt.depth, workers=1, frames=[0])).skipped_done == 1
    # computed again without it: the earlier PFMs go, so that none is read as this computation's
    redone = process_take(FarmOptions(take, tmp_path, opt.depth, workers=1, frames=[0], redo=True))
    assert redone.computed == 1 and not list((tmp_path / "depth").rglob("*.pfm"))


def test_ctrl_c_ends_with_one_line_and_nothing_from_dask(take: Path, tmp_path: Path) -> None:
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) while chunks run: our one line, exit
    130. It printed each worker's 'Async instruction ... ended with CancelledError', the nanny's 'Worker process
    still alive after 4.0 seconds, killing' and each worker's own KeyboardInterrupt traceback."""
    out = tmp_path / "p"
    with open(tmp_path / "stderr", "w") as err:
        proc = subprocess.Popen(
            [*rigctl_exe(), "process", str(take), "--out", str(out), "--workers", "2", *FAST],
            stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL, start_new_session=True,
        )  # fmt: skip
        try:
            deadline = time.monotonic() + 240
            while time.monotonic() < deadline and proc.poll() is None:  # until a chunk is done, others running
                ledger = out / "process.json"
                if ledger.exists() and '"done"' in ledger.read_text():
                    break
                time.sleep(0.2)
            assert proc.poll() is None, "the run ended before it could be interrupted"
            os.killpg(proc.pid, signal.SIGINT)
            assert proc.wait(timeout=120) == 130
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
    time.sleep(1)  # anything a worker still had to say
    lines = (tmp_path / "stderr").read_text().splitlines()
    assert lines[-1:] == ["rigctl process: interrupted"], lines
    noise = [ln for ln in lines if re.search(r"CancelledError|Traceback|KeyboardInterrupt|distributed|Worker", ln)]
    assert not noise, lines


def test_a_failed_frame_is_reported_and_the_others_complete(take: Path, tmp_path: Path) -> None:
    (tmp_path / "depth").mkdir()
    (tmp_path / "depth" / frame_name(1)).write_text("not a folder")  # frame 1 cannot be published
    res = run_rigctl("process", str(take), "--out", str(tmp_path), "--workers", "2", "--frames", "0-2", *FAST)
    assert res.returncode == 1
    # the frame's one line names the file in the way and why it was not written over
    assert re.search(r"frame 000001 failed: \S*depth/000001: is not a folder", res.stderr), res.stderr
    # said once, at the end (not again by the worker for each round of the range search)
    assert (res.stdout + res.stderr).count("depth/000001: is not a folder") == 1, res.stdout + res.stderr
    ledger = json.loads((tmp_path / "process.json").read_text())["frames"]
    assert ledger["000001"]["status"] == "failed" and "000001" in ledger["000001"]["error"]
    assert ledger["000000"]["status"] == ledger["000002"]["status"] == "done"


@pytest.mark.parametrize("url", ["http://127.0.0.1:8786", "tcp://127.0.0.1", "tcp://:8786", "tcp://h:99999", "x"])
def test_a_bad_scheduler_address_is_one_line(take: Path, tmp_path: Path, url: str) -> None:
    res = run_rigctl("process", str(take), "--out", str(tmp_path), "--scheduler", url)
    assert res.returncode == 2
    assert res.stderr.strip().count("\n") == 0 and "expected tcp://HOST:PORT" in res.stderr, res.stderr


def test_a_ledger_that_is_not_one_is_refused_in_one_line_naming_it(take: Path, tmp_path: Path) -> None:
    (tmp_path / "process.json").write_text('{"frames": {"000000": 5}}')  # ended in an AttributeError before
    res = run_rigctl("process", str(take), "--out", str(tmp_path), *FAST)
    assert res.returncode != 0 and res.stderr.count("\n") == 1, res.stderr
    assert f"{tmp_path / 'process.json'}: not a process ledger" in res.stderr and "frames.000000" in res.stderr


def test_a_folder_that_is_not_a_take_is_one_line(tmp_path: Path) -> None:
    res = run_rigctl("process", str(tmp_path / "nothing"), "--out", str(tmp_path / "out"))
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "not a take" in res.stderr, res.stderr


ONE = ("--frames", "0-0", "--workers", "1", "--preset", "fast", "--cameras", "r1c1", "--chunk", "1", "--warmup", "0")


@pytest.fixture(scope="module")
def processed(take: Path, module_tmp: Callable[[str], Path]) -> Path:
    """One frame set of the take through rigctl process (the first run the reruns below are checked against)."""
    return written(module_tmp("processed"), "process", str(take), *ONE)


def outputs(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(
    ("more", "words"),
    [
        (("--preset", "best"), "--preset fast, asked --preset best"),
        (("--near", "1", "--far", "5"), "no plan (--near/--far), asked --near 1.0 --far 5.0"),
        (("--cameras", "r1c0"), "--cameras r1c1, asked --cameras r1c0"),
        (("--no-key",), "keyed, asked --no-key"),
        (("--no-temporal",), "temporal, asked --no-temporal"),
        (("--chunk", "2"), "--chunk 1 --warmup 0, asked --chunk 2 --warmup 0"),
        (("--preset", "best", "--redo"), "--preset fast, asked --preset best"),  # --redo would keep frames of both
    ],
)
def test_a_rerun_with_other_settings_is_refused_naming_what_differs(
    take: Path, processed: Path, more: tuple[str, ...], words: str
) -> None:
    """The ledger kept only the chunking: a rerun with another preset or plan said "already done" and kept the
    first run's depth (and its "no plan" range) with exit 0."""
    before = outputs(processed)
    res = run_rigctl("process", str(take), "--out", str(processed), *ONE, *more)
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert words in res.stderr and "use a new --out" in res.stderr, res.stderr
    assert outputs(processed) == before


def test_a_rerun_on_another_take_or_a_changed_one_is_refused(take: Path, tmp_path: Path) -> None:
    import shutil

    from rigctl.take.manifest import read_manifest, write_manifest

    copy = tmp_path / "copy"
    shutil.copytree(take, copy)
    out = tmp_path / "out"
    assert run_rigctl("process", str(copy), "--out", str(out), *ONE).returncode == 0
    before = outputs(out)
    other = run_rigctl("process", str(take), "--out", str(out), *ONE)  # the same frames, another take folder
    assert other.returncode == 2 and other.stderr.count("\n") == 1, other.stderr
    assert f"take {copy.resolve()}, asked take {take.resolve()}" in other.stderr, other.stderr

    manifest = read_manifest(copy)
    manifest.mark("circled", "the crew's verdict changes no frame")
    write_manifest(copy, manifest)
    again = run_rigctl("process", str(copy), "--out", str(out), *ONE, "--json")
    assert again.returncode == 0 and json.loads(again.stdout)["skipped_done"] == 1, again.stderr

    manifest.take = "another"  # a take.yaml that is not the one the frame sets were computed from
    write_manifest(copy, manifest)
    changed = run_rigctl("process", str(copy), "--out", str(out), *ONE)
    assert changed.returncode == 2 and changed.stderr.count("\n") == 1, changed.stderr
    assert "the take's take.yaml with sha256" in changed.stderr and "use a new --out" in changed.stderr
    assert outputs(out) == before


def test_a_ledger_of_an_older_rigctl_is_refused_as_one_that_cannot_be_checked(take: Path, tmp_path: Path) -> None:
    assert run_rigctl("process", str(take), "--out", str(tmp_path), *ONE).returncode == 0
    path = tmp_path / "process.json"
    data = json.loads(path.read_text())
    data.pop("settings", None)  # as an older rigctl wrote it
    path.write_text(json.dumps(data))
    res = run_rigctl("process", str(take), "--out", str(tmp_path), *ONE)
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert f"{path}: written by an older rigctl" in res.stderr and "use a new --out" in res.stderr, res.stderr


@pytest.mark.parametrize("verb", ["process", "depth"])
@pytest.mark.parametrize("plan", [("--near", "3", "--far", "2"), ("--near", "2", "--far", "2")])
def test_a_plan_no_take_could_have_is_refused_on_the_client_before_any_folder(
    take: Path, tmp_path: Path, verb: str, plan: tuple[str, ...]
) -> None:
    """Checked on a Dask worker before: distributed's "Compute Failed" and a traceback, then our line, and an
    empty DIR/depth left behind. Now the options are checked as rigctl depth checks them, before anything."""
    out = tmp_path / "out"
    workers = ("--workers", "1") if verb == "process" else ()
    res = run_rigctl(verb, str(take), "--out", str(out), *workers, *FAST, *plan)
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "--near must be positive and below --far" in res.stderr, res.stderr
    assert not out.exists()
    with pytest.raises(ParameterError, match="below --far"):  # and through the API, before the folder too
        process_take(FarmOptions(take, out, DepthOptions(preset="fast", near_m=3.0, far_m=2.0), workers=1))
    assert not out.exists()


def test_a_plan_refused_on_the_worker_is_our_one_line_and_leaves_no_folder(take: Path, tmp_path: Path) -> None:
    """What only the take can tell (a --near whose disparity is beyond any number at this rig's focal length)
    is refused by the range task: distributed logged "Compute Failed" and a traceback before our line, and an
    empty DIR/depth was left."""
    out = tmp_path / "out"
    res = run_rigctl("process", str(take), "--out", str(out), *ONE, "--near", "1e-320", "--far", "1")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "--near 1e-320 m is too close to plan" in res.stderr and not out.exists()


def proc_io(pid: int) -> int:
    """Bytes the process has read and written through system calls (sockets included)."""
    fields = dict(line.split(": ") for line in Path(f"/proc/{pid}/io").read_text().splitlines())
    return int(fields["rchar"]) + int(fields["wchar"])


def dask_env() -> dict[str, str]:
    env = dict(os.environ, DASK_LOGGING__DISTRIBUTED="warning")
    env.update({v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")})
    return env


def wait_for(what: str, check, timeout: float = 120.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"gave up waiting for {what}")
        time.sleep(0.2)


@pytest.mark.slow
def test_subprocess_cluster_survives_a_killed_worker_and_keeps_images_off_the_scheduler(
    take: Path, single_process: Path, tmp_path: Path
) -> None:
    dask = str(Path(sys.executable).with_name("dask"))
    sched_file = tmp_path / "scheduler.json"
    common = {"env": dask_env(), "stdout": subprocess.DEVNULL, "stderr": subprocess.PIPE, "start_new_session": True}
    scheduler = [dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard"]
    procs = [subprocess.Popen([*scheduler, "--scheduler-file", str(sched_file)], **common)]
    try:
        wait_for("the scheduler", sched_file.exists, 60)
        worker = [dask, "worker", "--scheduler-file", str(sched_file), "--host", "127.0.0.1", "--nthreads", "1"]
        procs += [subprocess.Popen([*worker, "--no-dashboard", "--name", f"w{i}"], **common) for i in range(2)]
        address = json.loads(sched_file.read_text())["address"]
        import distributed

        with distributed.Client(address, timeout="30s") as c:
            c.wait_for_workers(2, timeout=90)
            # the scheduler unpickles task specs: it imports their modules once, reading files, not images
            c.run_on_scheduler(importlib.import_module, "rigctl.farm.frame")
        scheduler_io = proc_io(procs[0].pid)

        out = tmp_path / "out"
        argv = [*rigctl_exe(), "process", str(take), "--out", str(out), "--scheduler", address, *FAST, "--json"]
        client = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        ledger = out / "process.json"
        wait_for("the first frame", ledger.exists)
        os.killpg(procs[2].pid, signal.SIGKILL)  # the second worker and its nanny, mid-run
        procs[2].wait(30)
        stdout, stderr = client.communicate(timeout=300)
        assert client.returncode == 0, stderr
        handled = proc_io(procs[0].pid) - scheduler_io
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)

    summary = json.loads(stdout)
    assert summary["computed"] == FRAMES and summary["failed"] == 0
    assert summary["recomputed"] == (summary["search"]["rounds"] - 1) * FRAMES
    frames = json.loads(ledger.read_text())["frames"]
    assert all(e["status"] == "done" for e in frames.values()) and len(frames) == FRAMES
    for name in frames:
        assert same_bytes(single_process / name, out / "depth" / name) == []
    # the workers read 9 cameras of 480x270 UYVY per frame set from the take; the scheduler's reads and writes
    # (sockets and files) while the take was processed: about 26 kB here, a third of a frame set is the bar
    image_bytes = FRAMES * 9 * 480 * 270 * 2
    print(f"scheduler handled {handled} bytes; the workers read {image_bytes} bytes of images")
    assert handled < image_bytes / FRAMES / 3, (handled, image_bytes)


def test_a_frame_set_stays_within_the_worker_memory_bound(tmp_path: Path) -> None:
    from rigctl.farm.membench import STAGES
    from rigctl.farm.run import worker_memory_bytes

    res = run_rigctl("bench", "depth", "--size", "480x270", "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    r = json.loads(res.stdout)
    assert r["size"] == [480, 270] and len(r["cameras"]) == 9 and r["seconds"] > 0
    assert r["input_bytes"] == 9 * 480 * 270 * 3  # 8-bit BGR, as a rectified take reaches a worker
    assert r["input_bytes"] < r["peak_rss_bytes"] < worker_memory_bytes(480, 270, 9)
    # the frame set's peak is the larger of its depth's and its write's, each above the input held through both
    assert r["peak_rss_bytes"] == max(r["peak_rss_depth_bytes"], r["peak_rss_write_bytes"])
    assert min(r["peak_rss_depth_bytes"], r["peak_rss_write_bytes"]) > r["input_bytes"]
    # where the depth went: stages none of which lies within another, these work the presenter's first frame set
    # needs (no previous frame set to stabilise against, no cross-check in `best`: 0 s)
    stages = r["stages_s"]
    assert set(stages) == set(STAGES) and all(v >= 0 for v in stages.values())
    assert all(stages[k] > 0 for k in ("cost", "key", "sensor_fixed", "views_count", "occlusion_order"))
    assert sum(stages.values()) <= r["timings_s"]["depth"]
    # the kernels were loaded on a smaller frame set before the clock started: the timed one loaded none
    warm = r["warmup"]
    assert warm["size"] == [240, 135] and warm["seconds"] > 0 and warm["kernels"] > 0
    assert warm["loaded_while_timed"] == 0


def test_bench_size_refuses_a_bad_size() -> None:
    res = run_rigctl("bench", "depth", "--size", "4k")
    assert res.returncode == 2 and "--size: expected WIDTHxHEIGHT" in res.stderr and res.stderr.count("\n") == 1


def test_a_take_not_yet_rectified_is_rectified_on_the_workers_as_rigctl_rectify_would(tmp_path: Path) -> None:
    rig = (REPO / "rigs" / "sim-3x3.yaml").read_text()
    rig = rig.replace("width_px: 960", "width_px: 480").replace("height_px: 540", "height_px: 270")
    (tmp_path / "small.yaml").write_text(rig)
    res = run_rigctl(
        "record", str(tmp_path / "small.yaml"), "--take", "raw", "--frames", "2", "--out", str(tmp_path),
        "--sim", "motion=false", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    raw, calib = tmp_path / "raw", tmp_path / "raw" / "truth" / "calibration.yaml"
    refused = run_rigctl("process", str(raw), "--out", str(tmp_path / "p0"))
    assert refused.returncode == 2 and "not rectified: give --calibration" in refused.stderr, refused.stderr
    res = run_rigctl("process", str(raw), "--out", str(tmp_path / "p"), "--calibration", str(calib), *FAST)
    assert res.returncode == 0, res.stderr
    assert run_rigctl("rectify", str(raw), "--calibration", str(calib), "--out", str(tmp_path / "rect")).returncode == 0
    assert run_rigctl("depth", str(tmp_path / "rect"), "--out", str(tmp_path / "d"), *FAST).returncode == 0
    for name in ("000000", "000001"):
        assert same_bytes(tmp_path / "d" / name, tmp_path / "p" / "depth" / name) == []


def test_a_range_too_narrow_for_the_take_is_widened_for_every_chunk_alike_in_depth_and_process(
    take: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A measured range that clips the nearest part of the presenter: each chunk of the first round widens it
    on its own, so every chunk is run again from the hull of their widenings. Then every frame set searched that
    one range (none narrower than an earlier one), in ``rigctl depth`` and in ``rigctl process`` byte for byte."""
    import numpy as np

    import rigctl.depth.pipeline as pipeline
    from rigctl.depth.run import run_depth
    from rigctl.depth.sources import open_source
    from rigctl.depth.take_range import RangeDecision, decide_range
    from rigctl.farm.ledger import Ledger
    from rigctl.farm.run import run_settings
    from rigctl.take.manifest import read_manifest

    opt = DepthOptions(preset="fast", cameras=CAMS, chunk=CHUNK, warmup=WARMUP)
    src = open_source(take)
    truths = [src.grid(n).truth for n in src.frame_numbers()]
    top = max(float(np.nanmax(np.where(np.isfinite(t[c]), t[c], np.nan))) for t in truths if t for c in CAMS)
    measured = decide_range(src, opt)
    narrow = RangeDecision(
        disparity_range_px=(measured.disparity_range_px[0], top - 3.0), source="measured (test)", planned=False
    )
    monkeypatch.setattr(pipeline, "decide_range", lambda _src, _opt: narrow)
    report = run_depth(take, tmp_path / "d", opt, formats=("pfm", "png", "exr"))
    search = report.search
    assert search is not None and search.rounds >= 2 and search.settled and search.widenings, search
    lo, hi = search.state.disparity_range_px
    assert lo <= narrow.disparity_range_px[0] and hi > top  # the hull covers the scene
    ranges = [f.disparity_range_px for f in report.frames.values()]
    assert ranges == [(lo, hi)] * FRAMES  # every frame set searched the final range: none narrower than before
    assert report.widenings == [] and all("(widened)" in f.range_source for f in report.frames.values())

    ledger = Ledger(tmp_path / "p")  # the farm from the same measured range (a measured range is kept)
    ledger.data.settings = run_settings(FarmOptions(take, tmp_path / "p", opt), read_manifest(take))
    ledger.data.range = narrow
    ledger.save()
    res = run_rigctl("process", str(take), "--out", str(tmp_path / "p"), "--workers", "2", *FAST, "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["search"] == search.model_dump(mode="json")  # the same rounds, whatever order chunks finished in
    # the progress counts each round's frame sets apart: the take's, not the take's times the rounds
    again = (search.rounds - 1) * FRAMES
    assert f": {FRAMES} of {FRAMES} frame sets (and {again} in earlier passes) in " in res.stderr, res.stderr
    # every frame set counted once, the rounds after the first apart (they were counted as frame sets)
    assert summary["computed"] == FRAMES and summary["failed"] == 0 and summary["chunks"] == FRAMES // CHUNK
    assert summary["recomputed"] == (search.rounds - 1) * FRAMES
    assert summary["chunks_recomputed"] == (search.rounds - 1) * FRAMES // CHUNK
    assert sum(summary["frames_by_worker"].values()) == FRAMES and summary["frames"] == FRAMES
    written = json.loads((tmp_path / "p" / "process.json").read_text())
    assert written["search"] == summary["search"] and written["chunk"] == CHUNK and written["warmup"] == WARMUP
    for name, entry in written["frames"].items():
        assert entry["start"] == summary["search"]["state"]
        assert entry["report"]["disparity_range_px"] == [lo, hi]
        assert same_bytes(tmp_path / "d" / name, tmp_path / "p" / "depth" / name) == []
    # a resume with another chunking is refused in one line (its outputs would not be these)
    other = run_rigctl("process", str(take), "--out", str(tmp_path / "p"), *FAST, "--chunk", "3")
    assert other.returncode == 2 and other.stderr.count("\n") == 1 and "--chunk 2" in other.stderr, other.stderr
    again = run_rigctl("process", str(take), "--out", str(tmp_path / "p"), *FAST, "--json")
    assert again.returncode == 0 and json.loads(again.stdout)["skipped_done"] == FRAMES, again.stderr


def test_a_frame_set_computed_again_after_the_range_widened_is_counted_once(take: Path, tmp_path: Path) -> None:
    """One frame set, one chunk, a measured range that clips the presenter: its chunk widens the range and runs
    again. It said "2 frame sets computed in 2 chunks" (on a 3-frame take, computed 6 and chunks 6)."""
    import numpy as np

    from rigctl.depth.sources import open_source
    from rigctl.depth.take_range import RangeDecision, decide_range
    from rigctl.farm.ledger import Ledger
    from rigctl.farm.run import run_settings
    from rigctl.take.manifest import read_manifest

    opt = DepthOptions(preset="fast", cameras=("r1c1",), chunk=1, warmup=0)
    src = open_source(take)
    truth = src.grid(0).truth["r1c1"]
    top = float(np.nanmax(np.where(np.isfinite(truth), truth, np.nan)))
    low = decide_range(src, opt).disparity_range_px[0]
    for out in (tmp_path / "json", tmp_path / "text"):
        out.mkdir()
        ledger = Ledger(out)
        ledger.data.settings = run_settings(FarmOptions(take, out, opt), read_manifest(take))
        ledger.data.range = RangeDecision(disparity_range_px=(low, top - 3.0), source="measured (test)", planned=False)
        ledger.save()
    res = run_rigctl("process", str(take), "--out", str(tmp_path / "json"), *ONE, "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["search"]["rounds"] == 2, summary["search"]  # the chunk ran twice
    assert (summary["frames"], summary["computed"], summary["chunks"]) == (1, 1, 1)
    assert (summary["recomputed"], summary["chunks_recomputed"]) == (1, 1)
    assert summary["frames_by_worker"] and sum(summary["frames_by_worker"].values()) == 1
    assert summary["frames_per_second"] == pytest.approx(1 / summary["compute_seconds"])

    text = run_rigctl("process", str(take), "--out", str(tmp_path / "text"), *ONE)  # in words: said apart
    assert text.returncode == 0, text.stderr
    assert "1 frame sets computed in 1 chunks (1 chunks, 1 frame sets, run again after the range widened)" in (
        text.stdout
    ), text.stdout


def test_local_workers_allocate_as_rigctl_depth_does(tmp_path: Path) -> None:
    """Dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which also pins glibc's mmap threshold at
    128 KB: every array over it mapped and unmapped, its pages faulted in each time (71 s of system time
    against 8 s for the demo's take). rigctl's local workers start without it; Dask's other settings stay."""
    import os

    from rigctl.farm.run import FarmOptions, dask_client

    with dask_client(FarmOptions(take=tmp_path, out=tmp_path, workers=1, memory_limit="1GiB")) as client:
        # os.getenv goes by name, and runs in the worker
        trim = list(client.run(os.getenv, "MALLOC_TRIM_THRESHOLD_").values())
        omp = list(client.run(os.getenv, "OMP_NUM_THREADS").values())
    assert trim == [None] and omp == ["1"]
