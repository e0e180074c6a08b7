"""A careless or hostile user, part two: serial lines and services, the plan at its edges, rig files, the
command line, and resources and races. Each case asserts the one line and the documented exit status.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hostile_support import REPO, SIM_RIG, one_line, rig_with, write_yaml  # type: ignore[import-not-found]
from tests_support import make_non_device, rigctl_exe  # type: ignore[import-not-found]

from rigctl.errors import EXIT_BAD_INPUT, EXIT_DEVICE, EXIT_USAGE

# ---- 4. serial lines and services ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (("--program", "r1c1", "r1c1"), "--program: camera r1c1 is named twice"),
        (("--preview", "r0c0", "r1c0", "r0c0"), "--preview: camera r0c0 is named twice"),
    ],
)
def test_tally_refuses_a_camera_named_twice(  # type: ignore[no-untyped-def]
    run_cli, tmp_path: Path, argv: tuple[str, ...], fragment: str
) -> None:
    """A name twice in one list is a typing slip: refused on the shipped rig, and before the line is opened (a
    rig whose port is missing says the same, not a device error). Program and preview at once is a state
    (test_tally_pty.py)."""
    one_line(run_cli("tally", "sim-3x3", *argv), EXIT_USAGE, fragment)
    rig = rig_with(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": "/nonexistent/ttyUSB9"})
    one_line(run_cli("tally", str(rig), *argv), EXIT_USAGE, fragment)


@pytest.mark.parametrize("port", ["foo://bar", "/dev/null", "/nonexistent/ttyUSB9"])
def test_tally_transport_failures_are_device_errors_naming_the_port(run_cli, tmp_path: Path, port: str) -> None:  # type: ignore[no-untyped-def]
    rig = rig_with(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": port})
    one_line(run_cli("tally", str(rig), "--program", "r0c0"), EXIT_DEVICE, f"{port}: ")


@pytest.mark.parametrize("kind", ["a folder", "a regular file", "a FIFO"])
def test_a_tally_port_that_exists_but_is_no_device_says_what_it_is(run_cli, tmp_path: Path, kind: str) -> None:  # type: ignore[no-untyped-def]
    """It said 'no such serial port' for a folder, which exists."""
    port = make_non_device(tmp_path / "port", kind)
    rig = rig_with(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": str(port)})
    one_line(run_cli("tally", str(rig), "--program", "r0c0"), EXIT_DEVICE, f"{port}: exists but is {kind}, not a")


def test_a_take_path_that_exists_but_is_no_folder_says_what_it_is(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """It said 'no such take folder' for /dev/null, which exists."""
    (tmp_path / "afile").write_text("")
    for path, what in (("/dev/null", "a device"), (str(tmp_path / "afile"), "a file")):
        one_line(run_cli("take", "info", path), EXIT_BAD_INPUT, f"{path}: exists but is {what}, not a take folder")
    one_line(run_cli("take", "info", str(tmp_path / "none")), EXIT_BAD_INPUT, "none: no such take folder")


def test_control_with_unknown_bridge_scheme_is_a_device_error(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    rig = rig_with(tmp_path, camera_control={"bridge": "foo://bar"})
    expected = "bridge: device address 'foo://bar': unknown scheme"
    one_line(run_cli("control", str(rig), "--gain", "2"), EXIT_DEVICE, expected)


def test_a_pty_line_opens_again_with_even_parity(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    master, slave = os.openpty()
    try:
        rig = rig_with(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": os.ttyname(slave)})
        for _ in range(3):  # the second open of a configured pty with parity E was EINVAL
            res = run_cli("tally", str(rig), "--program", "r0c0")
            assert res.returncode == 0, res.stderr
            assert len(os.read(master, 4096)) > 0
    finally:
        os.close(master)
        os.close(slave)


# ---- 5. plan at the edges ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs",
    [
        {"near_m": 1, "far_m": 1e155},
        {"subject_depth_m": 1e200},
        {"near_m": 1e300, "far_m": 1.7e308},
        {"near_m": 1e-300, "far_m": 1},
    ],
)
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # what becomes null in the JSON
def test_plan_json_is_valid_at_any_finite_input(kwargs: dict[str, float]) -> None:
    """The planner's JSON at any finite input (the CLI refuses distances outside 1 mm to 1,000 km before it)."""
    from rigctl.planning.report import plan_rig
    from rigctl.rig import load_rig

    text = json.dumps(plan_rig(load_rig("sim-3x3"), **kwargs).as_json(), allow_nan=False)
    plan = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in JSON"))
    assert all(plan[k] is None or np.isfinite(plan[k]) for k in ("near_m", "c0_px", "max_spacing_x_m"))
    for key in plan.get("not_representable", []):  # what is out of double range is named, not inf
        node: Any = plan
        for part in key.split("."):
            node = node[part]
        assert node is None


def test_plan_nearer_than_double_range_is_one_line(run_cli) -> None:  # type: ignore[no-untyped-def]
    from rigctl.errors import ParameterError
    from rigctl.planning.report import plan_rig
    from rigctl.rig import load_rig

    one_line(run_cli("plan", "--near", "1e-307", "--far", "1", "--json"), EXIT_USAGE, "--near 1e-307 m: a plan's")
    with pytest.raises(ParameterError, match="near_m 1e-307 is so close"):
        plan_rig(load_rig("sim-3x3"), near_m=1e-307, far_m=1)


def test_64x64_plan_groups_pairs_by_offset(tmp_path: Path) -> None:
    from rigctl.planning.report import plan_rig
    from rigctl.rig import load_rig

    n = 64
    rig = dict(
        SIM_RIG,
        grid={**SIM_RIG["grid"], "rows": n, "columns": n},
        cameras=[{"name": f"r{r}c{c}", "device": f"sim://{r}/{c}"} for r in range(n) for c in range(n)],
    )
    rig.pop("tally"), rig.pop("camera_control")
    plan = plan_rig(load_rig(write_yaml(tmp_path / "g.yaml", rig)), subject_depth_m=1.0)
    assert plan.pair_count == (n * n) * (n * n - 1) // 2 and plan.pairs_grouped
    assert len(plan.pairs) == n * n - 1  # one per offset (rows >= 0, |columns|) but (0, 0)
    assert sum(p.same_offset_pairs for p in plan.pairs) == plan.pair_count
    ref = next(p for p in plan.pairs if p.name == plan.reference_pair)
    assert ref.same_offset_pairs == n * (n - 1) and ref.fraction_of_width == pytest.approx(0.04)


def test_grouped_and_listed_plans_agree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from rigctl.planning import report as plan_report
    from rigctl.planning.text import format_plan
    from rigctl.rig import load_rig

    rig = load_rig("sim-3x3")
    listed = plan_report.plan_rig(rig, near_m=1.5, far_m=2.5)
    monkeypatch.setattr(plan_report, "LIST_PAIRS_UP_TO", 0)
    grouped = plan_report.plan_rig(rig, near_m=1.5, far_m=2.5)
    assert grouped.pairs_grouped and len(grouped.pairs) < len(listed.pairs) == grouped.pair_count == 36
    by_name = {p.name: p for p in listed.pairs}
    for g in grouped.pairs:
        same = [p for p in listed.pairs if (p.dx_m, p.dy_m) == pytest.approx((g.dx_m, g.dy_m))]
        assert len(same) == g.same_offset_pairs and by_name[g.name].parallax_px == g.parallax_px
    assert grouped.over_budget_count == listed.over_budget_count == len(listed.over_budget)
    assert all(p.same_offset_pairs == 1 for p in listed.pairs)
    assert f"{len(listed.over_budget)} of 36 pairs exceed the budget" in format_plan(listed, rig)


# ---- 6. rig files ---------------------------------------------------------------------------------------------

RIG_TEXT = (REPO / "rigs" / "sim-3x3.yaml").read_text().split("# Camera control through")[0]


def _line(text: str, needle: str, nth: int = 1) -> int:
    lines = [i + 1 for i, ln in enumerate(text.splitlines()) if needle in ln]
    return lines[nth - 1]


@pytest.mark.parametrize(
    ("old", "new", "needle", "nth", "message"),
    [
        (
            "    device: sim://r2c2",
            "    device: sim://r2c1",
            "device: sim://r2c1",
            2,
            "cameras[8].device sim://r2c1 is used by two cameras (cameras[7] too)",
        ),
        (
            "  - name: r2c2",
            "  - name: r1c1",
            "name: r1c1",
            2,
            "cameras[8].name r1c1 appears twice (first as cameras[4])",
        ),
        ("  - name: r2c2", "  - name: r2c5", "name: r2c5", 1, "cameras[8].name r2c5 lies outside the 3x3 grid"),
        ("  rows: 3", "  rows: 4", "rows: 4", 1, "grid.rows is 4 but the cameras use rows 0-2: make it 3"),
        ("  columns: 3", "  columns: 5", "columns: 5", 1, "grid.columns is 5 but the cameras use columns 0-2"),
        ("  rows: 3", "  rows: true", "rows: true", 1, "grid.rows must be a number, got true (a boolean)"),
        ("  fps: 25", "  fps: false", "fps: false", 1, "format.fps must be a number, got false (a boolean)"),
        ("  width_px: 960", "  width_px: '960'", "width_px", 1, "format.width_px must be a whole number, got '960'"),
        (
            "  spacing_x_m: 0.120",
            "  spacing_x_mm: 0.120",
            "spacing_x_mm",
            1,
            "grid.spacing_x_mm is not a known field; did you mean 'spacing_x_m'?",
        ),
        ("  fps: 25", "  fsp: 25", "fsp", 1, "format.fsp is not a known field; did you mean 'fps'?"),
        ("lens:", "lenz:", "lenz", 1, "lenz is not a known field; did you mean 'lens'?"),
        (
            "  fps: 25",
            "  fps: 25\n  pixelformat: UYVY",
            "pixelformat",
            1,
            "format.pixelformat is not a known field; did you mean 'pixel_format'?",
        ),
    ],
)
def test_rig_file_errors_name_the_offending_line(  # type: ignore[no-untyped-def]
    run_cli, tmp_path: Path, old: str, new: str, needle: str, nth: int, message: str
) -> None:
    assert old in RIG_TEXT
    text = RIG_TEXT.replace(old, new, 1)
    rig = tmp_path / "rig.yaml"
    rig.write_text(text)
    one_line(run_cli("plan", str(rig)), EXIT_BAD_INPUT, f"{rig}:{_line(text, needle, nth)}: {message}")


# ---- 7. the command line --------------------------------------------------------------------------------------


def test_exit_codes_are_documented_in_readme_and_errors() -> None:
    import rigctl.errors as errors

    readme = (REPO / "README.md").read_text()
    for code, name in ((1, "check failed"), (2, "usage"), (3, "bad input file"), (4, "device"), (5, "data damaged")):
        assert f"| {code} | {name}" in readme
        assert f"{code}     " in (errors.__doc__ or "")
    assert (errors.DeviceError.exit_code, errors.ProtocolError.exit_code) == (4, 4)
    assert (errors.RigFileError.exit_code, errors.TakeError.exit_code, errors.CalibrationError.exit_code) == (3, 3, 3)
    assert (errors.DamagedDataError.exit_code, errors.ParameterError.exit_code) == (5, 2)


def test_closed_pipe_is_quiet(tmp_path: Path) -> None:
    exe = " ".join(rigctl_exe())
    res = subprocess.run(
        f"{exe} plan rigs/bmd-micro-studio-4k-3x3.yaml --json | head -1; {exe} plan --json | head -c 1",
        shell=True,
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert res.stdout.startswith("{\n{") and res.stderr == ""


@pytest.mark.parametrize(
    ("redirect", "fragment"),
    [("> /dev/full", "stdout (/dev/full): cannot write the output: no space left on the device"),
     (">&-", "stdout is closed")],
)  # fmt: skip
@pytest.mark.parametrize("argv", ["plan", "plan --json", "--help", "board --help"])
def test_a_full_or_closed_stdout_is_one_line(tmp_path: Path, redirect: str, fragment: str, argv: str) -> None:
    exe = " ".join(rigctl_exe())
    res = subprocess.run(
        f"{exe} {argv} {redirect}", shell=True, capture_output=True, text=True, cwd=tmp_path, timeout=120
    )
    one_line(res, EXIT_DEVICE, fragment)


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--size", "64x36", "--repeats", "0"], "--repeats applies to the preset table"),  # ran, ignoring it
        (["--size", "64x36", "--video"], "--size and --video are two different benches"),  # ran --size alone
        (["--video", "--cameras", "r1c1"], "--cameras applies to --size, not to --video"),
        (["--frames", "4"], "--frames applies to --video, not to the preset table"),
        (["--repeats", "0"], "--repeats must be at least 1, got 0"),
    ],
)
def test_bench_depth_refuses_what_the_chosen_bench_would_ignore(tmp_path: Path, argv: list[str], says: str) -> None:
    res = subprocess.run(
        [*rigctl_exe(), "bench", "depth", *argv], capture_output=True, text=True, cwd=tmp_path, timeout=300
    )
    one_line(res, EXIT_USAGE, says)
    assert not list(tmp_path.iterdir())  # refused before any work: no plot


@pytest.mark.parametrize("repeats", ["0", "1001", "99999999999999999999"])
def test_bench_render_repeats_are_bounded(tmp_path: Path, repeats: str) -> None:
    """An absurd --repeats ran until killed (the pairs are timed one after the other)."""
    res = subprocess.run(
        [*rigctl_exe(), "bench", "render", "--size", "64x36", "--repeats", repeats],
        capture_output=True, text=True, cwd=tmp_path, timeout=300,
    )  # fmt: skip
    one_line(res, EXIT_USAGE, f"--repeats must be 1 to 1000, got {repeats}")


def test_python_dash_m_and_debug_anywhere(tmp_path: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "rigctl", "plan", "--near", "3", "--far", "2"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    one_line(res, EXIT_USAGE, "rigctl plan: error: far_m must be >= near_m")
    for argv in (
        ["--debug", "plan", "--near", "3", "--far", "2"],
        ["plan", "--near", "3", "--debug", "--far", "2"],
        ["plan", "--near", "3", "--far", "2", "--debug"],
    ):
        res = subprocess.run([sys.executable, "-m", "rigctl", *argv], capture_output=True, text=True, cwd=tmp_path)
        assert res.returncode != 0 and "Traceback" in res.stderr and "ParameterError" in res.stderr, argv


# ---- resources and races -------------------------------------------------------------------------------------


def test_sdi_bridge_decoder_keeps_bounded_error_history() -> None:
    from rigctl.drivers.protocols.sdi_bridge import SYNC, FrameDecoder

    dec = FrameDecoder()
    rng = np.random.default_rng(3)
    for _ in range(100):  # 400 KB of garbage full of false syncs
        chunk = bytearray(rng.integers(0, 256, 4000, dtype=np.uint8).tobytes())
        for i in range(0, 4000, 20):
            chunk[i : i + 2] = SYNC
        dec.feed(bytes(chunk))
    assert dec.error_count > 5_000 and len(dec.errors) == FrameDecoder.KEEP_ERRORS


def test_killed_take_reserve_is_removed_when_next_read(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import fcntl
    import signal
    import time

    from rigctl.take.reserve import create_reserve, remove_stale_reserves

    proc = subprocess.Popen(
        [
            *rigctl_exe(),
            "record",
            "--take",
            "k",
            "--frames",
            "2000",
            "--out",
            str(tmp_path),
            "--sim",
            "motion=false",
            "--force",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        stdin=subprocess.DEVNULL,
    )
    take = tmp_path / ".k.rigctl-recording"  # recorded under its hidden name until its end (take/staging.py)
    index = take / "cameras" / "r2c2.index"
    for _ in range(1200):  # waits for the state, asserts nothing about time
        if index.exists() and index.stat().st_size >= 4 * 64:
            break
        time.sleep(0.05)
    reserve = take / ".reserve"
    assert reserve.exists()
    # while the recorder runs, its reserve is not stale
    assert remove_stale_reserves([take]) == []
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert reserve.exists() and reserve.stat().st_size == 1 << 20
    res = run_cli("take", "check", str(take))
    assert res.returncode == 0, res.stderr
    assert not reserve.exists()
    # a reserve this process holds is left alone
    fd = create_reserve(tmp_path, 16)
    try:
        assert remove_stale_reserves([tmp_path]) == [] and (tmp_path / ".reserve").exists()
        fcntl.flock(fd, fcntl.LOCK_UN)
        assert remove_stale_reserves([tmp_path]) == [tmp_path / ".reserve"]
    finally:
        os.close(fd)


def test_writers_close_only_after_the_flush_thread_ends(tmp_path: Path) -> None:
    """'flushing r2c2: Bad file descriptor' at the end of a take: the flush thread was still syncing files the
    ending take had closed. A flush that began before the end must end before any writer closes."""
    import threading
    import time

    from rigctl.capture.recorder import Recorder, TakePlan
    from rigctl.registry import open_cameras
    from rigctl.rig import load_rig
    from rigctl.take.writer import CameraWriter

    trace: list[str] = []
    syncing = threading.Event()
    holder: dict[str, Recorder] = {}

    class Traced(CameraWriter):
        def sync(self) -> None:
            if threading.current_thread().name != "syncer":  # close() syncs its own files last: not traced
                super().sync()
                return
            trace.append("sync-start")
            syncing.set()
            holder["rec"]._finished.wait(30)  # a slow flush: still running when the take ends
            trace.append("sync-end")
            super().sync()

        def close(self) -> None:
            trace.append("close")
            super().close()

    rig = load_rig("sim-3x3")
    devices = open_cameras(rig, ["motion=false", "noise=0"], ["r0c0", "r0c1"])
    plan = TakePlan.spread("t", [tmp_path], sorted(devices.cameras))
    rec = holder["rec"] = Recorder(rig, devices, plan, writer_factory=Traced)
    rec.sync_interval_s = 0.01
    rec.arm()
    rec.start(200)
    assert syncing.wait(30)
    for _ in range(1200):  # a frame on disk first: a take that kept no frame is not kept at all
        if any(st.written for st in rec.stats.values()):
            break
        time.sleep(0.05)
    rec.stop()
    man = rec.finish()
    assert man is not None and man.status in ("complete", "ended") and "close" in trace
    first_close = trace.index("close")
    assert trace[:first_close].count("sync-start") == trace[:first_close].count("sync-end")
    assert "sync-start" not in trace[first_close:]


def test_tally_service_never_dies_silently(tmp_path: Path) -> None:
    """The service on a port with an unknown scheme: the error shows in its state and it keeps retrying; on
    an error that is not the line's (a bug) it stops, and says so."""
    import threading

    from rigctl.errors import DeviceError
    from rigctl.registry import open_tally
    from rigctl.rig import load_rig
    from rigctl.tally import TallyService, TallyState

    rig = load_rig(rig_with(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": "foo://bar"}))
    attempts: list[str] = []
    retried = threading.Event()

    def opener() -> Any:
        attempts.append("open")
        if len(attempts) >= 3:
            retried.set()
        return open_tally(rig)

    svc = TallyService(opener, port_path="foo://bar")
    svc.BACKOFF_S = (0.0,)  # retry at once: the test waits for attempts, not for time
    svc.start()
    try:
        assert retried.wait(30)
        assert not svc.connected and svc.running and svc.stopped_by == ""
        assert svc.last_error.startswith("foo://bar: cannot open serial port")
    finally:
        svc.stop()
    with pytest.raises(DeviceError, match="foo://bar"):
        open_tally(rig)

    def broken() -> Any:
        raise ValueError("a bug in an output driver")

    svc = TallyService(broken).start()
    svc._thread.join(30)
    assert not svc.running and not svc.connected
    assert svc.last_error == svc.stopped_by == "tally service stopped: ValueError: a bug in an output driver"
    svc.set(TallyState(program=frozenset({"r0c0"})))  # setting state on a stopped service does not hang


LONG_PATH = "a/" * 2500  # 5,000 characters: more than PATH_MAX (4,096)


@pytest.mark.parametrize("problem", ["too long", "a loop"])
@pytest.mark.parametrize(
    ("argv", "what"),
    [
        (("depth", "{p}", "--out", "out"), "INPUT"),
        (("take", "info", "{p}"), "TAKE"),
        (("take", "export", "{p}", "--out", "out"), "TAKE"),
        (("render", "{p}", "--disparity", ".", "--at", "0,0", "--out", "o.png"), "INPUT"),
        (("render", ".", "--disparity", "{p}", "--path", "0,0", "1,0", "--out", "o.mp4"), "--disparity"),
        (("rectify", "{p}", "--calibration", "c.yaml", "--out", "out"), "TAKE"),
        (("rectify", ".", "--calibration", "{p}", "--out", "out"), "--calibration"),
        (("plan", "{p}"), "RIG"),
        (("view", "{p}", "--disparity", "."), "INPUT"),
    ],
)
def test_an_input_path_the_system_cannot_look_up_is_the_inputs_fault(  # type: ignore[no-untyped-def]
    run_cli, tmp_path: Path, argv: tuple[str, ...], what: str, problem: str
) -> None:
    """A 5,000-character input path (ENAMETOOLONG) or a loop of symbolic links (ELOOP) ended in 'cannot write'
    with exit 4 (the output side's catch-all), or a RuntimeError traceback: it is the input's fault, exit 3, in
    one line naming the argument, the path shortened, and refused before any output folder is made."""
    if problem == "a loop":
        (tmp_path / "loop").symlink_to("loop")
        path, says = "loop/x", f"{what} loop/x: a loop of symbolic links"
    else:
        path, says = LONG_PATH, "(5,000 characters): the path is too long for the file system"
    line = one_line(run_cli(*(a.replace("{p}", path) for a in argv)), EXIT_BAD_INPUT, f"error: {what} ", says)
    assert len(line) < 200 and "cannot write" not in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv", [("board", "--out", LONG_PATH + "b"), ("depth", ".", "--out", LONG_PATH)])
def test_an_output_path_too_long_still_cannot_be_written(run_cli, argv: tuple[str, ...]) -> None:  # type: ignore[no-untyped-def]
    """The other side of the above: a too-long output path is the destination's problem (exit 4), said in one
    line with the path shortened."""
    line = one_line(run_cli(*argv), EXIT_DEVICE, "a/a/a/...", "characters): cannot write: File name too long")
    assert len(line) < 200


def test_an_output_path_in_a_loop_of_symbolic_links_cannot_be_written(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """depth's and rectify's check of --out against the input ended in a RuntimeError traceback (Path.resolve on
    a symlink loop): the destination's problem, exit 4, one line."""
    (tmp_path / "loop").symlink_to("loop")
    one_line(run_cli("depth", ".", "--out", "loop/x"), EXIT_DEVICE, "loop/x: ", "Too many levels of symbolic links")
    res = run_cli("rectify", ".", "--calibration", "c.yaml", "--out", "loop/x")
    assert res.returncode in (EXIT_BAD_INPUT, EXIT_DEVICE) and "Traceback" not in res.stderr, res.stderr
