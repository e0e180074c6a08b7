"""The shoot UI on the simulated rig, driven by Textual's pilot (real session, real cameras, real takes on
disk), snapshots of its screens with fixed data, and a run in a real terminal (tmux)."""

from __future__ import annotations

import asyncio
import faulthandler
import shutil
import subprocess
import tempfile
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from tests_support import rigctl_exe

from rigctl.capture.preflight import WriteSpeed
from rigctl.interfaces import SettingResult, SettingState
from rigctl.rig import load_rig, rig_from_dict
from rigctl.take.reader import TakeReader
from rigctl.tui.app import ShootApp
from rigctl.tui.screens import Confirm, HelpScreen, Notice, PlannerScreen, Refused
from rigctl.tui.session import Session, Snapshot, TileStatus
from rigctl.tui.tiles import CameraTile

# The shipped sim rig at half its size: these tests are about the shoot UI, and a quarter of the pixels keeps
# a shared CI machine's capture threads from starving (the recorder's throughput is tested elsewhere)
SHIPPED = load_rig("sim-3x3")
_data = SHIPPED.to_dict()
_data["format"].update(width_px=480, height_px=270)
RIG = rig_from_dict(_data, "sim-3x3 at 480x270")
SIM = ["motion=false", "noise=0"]


def run(app: ShootApp, script: Callable[[Any], Awaitable[None]], size: tuple[int, int] = (170, 60)) -> None:
    async def main() -> None:
        async with app.run_test(size=size) as pilot:
            await script(pilot)

    asyncio.run(main())


async def until(pilot: Any, cond: Callable[[], bool], timeout: float = 60.0, what: str = "") -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            faulthandler.dump_traceback(all_threads=True)  # where the session's threads are stuck
            screen = pilot.app.screen
            said = f": the screen says {screen.title_text!r} {screen.lines}" if isinstance(screen, Notice) else ""
            raise AssertionError(f"timed out waiting for {what}{said}; session message {pilot.app.session.message!r}")
        await pilot.pause(0.1)


@pytest.fixture
def fast_out(tmp_path: Path):  # type: ignore[no-untyped-def]
    """Takes go to memory (tmpfs): the UI's preflight measures the disk, and a shared CI disk can be too slow
    for nine cameras, which is a refusal these tests do not mean to test."""
    shm = Path("/dev/shm")
    folder = Path(tempfile.mkdtemp(dir=shm)) if shm.is_dir() else tmp_path / "takes"
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def live_app(out: Path, sim: list[str] | None = None) -> ShootApp:
    return ShootApp(lambda: Session(RIG, out, [*SIM, *(sim or [])]))


async def armed(pilot: Any) -> None:
    app = pilot.app
    await until(pilot, lambda: app.session is not None and app.session.recorder is not None, what="arming")
    await until(pilot, lambda: app.snapshots_shown > 2, what="the first snapshots")


async def record(pilot: Any, seconds: float, stall_s: float = 0.0) -> tuple[int, int]:
    """Record a take; with ``stall_s`` the UI's own thread computes that long without yielding (no events,
    no redraws). Returns the stall's start and end on CLOCK_MONOTONIC."""
    app = pilot.app
    await pilot.press("r")
    await until(pilot, lambda: app.session.recording, what="recording to start")
    await pilot.pause(seconds)
    stall = (time.monotonic_ns(), time.monotonic_ns())
    if stall_s:
        end = time.monotonic() + stall_s
        while time.monotonic() < end:
            pass
        stall = (stall[0], time.monotonic_ns())
    await pilot.press("r")
    await until(pilot, lambda: not app.session.recording and not app.session.busy, what="the take to end")
    return stall


def test_r_records_a_take_of_every_camera(fast_out: Path) -> None:
    tmp_path = fast_out
    app = live_app(tmp_path)

    async def script(pilot: Any) -> None:
        await armed(pilot)
        await record(pilot, 1.5)
        assert "S01-01-T01 written to" in app.session.message and app.session.take_number == 2
        await pilot.press("q")

    run(app, script)
    take = TakeReader(tmp_path / "S01-01-T01")
    assert sorted(take.names) == sorted(RIG.camera_names)
    # every instant of the take is a frame or an accounted drop on every camera (an overloaded machine may
    # drop; it may not lose a frame without saying so)
    slots = len(take.frame_sets)
    for n in take.names:
        cam = take.manifest.cameras[n]
        accounted = len(cam.source_drops) + len(cam.writer_drops) + len(cam.not_written)
        assert len(take.index[n]) + accounted == slots, (n, len(take.index[n]), accounted, slots)
    assert len(take.complete_sets()) >= 20


def test_a_drop_on_one_camera_shows_on_its_tile(fast_out: Path) -> None:
    tmp_path = fast_out
    drops = list(range(30, 2000, 7))
    app = live_app(tmp_path, [f"drops.r1c2={drops}"])

    async def script(pilot: Any) -> None:
        await armed(pilot)
        await pilot.press("r")
        await until(pilot, lambda: app.session.recording, what="recording")
        tile = app.query_one("#tile-r1c2", CameraTile)

        def injected_in_take() -> int:  # the recorder's own count: a loaded machine may drop frames of its own
            rec = app.session.recorder
            return len(set(rec.stats["r1c2"].source_drops) & set(drops)) if rec is not None else 0

        # three of the injected drops inside the take, not any three (under load the first drops counted may
        # be the machine's, and a take stopped then holds too few injected ones to judge)
        await until(pilot, lambda: injected_in_take() >= 3, what="three injected drops on r1c2")
        await until(pilot, lambda: tile.last is not None and tile.last.source_drops >= 3, what="drops on r1c2")
        assert tile.has_class("problem")
        assert "drops src" in str(tile.render())
        await pilot.press("r")
        await until(pilot, lambda: not app.session.recording and not app.session.busy, what="the take to end")
        await pilot.press("q")

    run(app, script)
    take = TakeReader(tmp_path / "S01-01-T01")
    # the injected drops are r1c2's and only r1c2's (a loaded machine may add a few drops of its own anywhere)
    r1c2 = take.manifest.cameras["r1c2"]
    injected = {d for d in drops if r1c2.first_sequence < d < r1c2.last_sequence}
    assert len(injected) >= 3 and injected <= set(r1c2.source_drops)
    # r1c2's pattern leaking to another camera would drop every injected sequence there, and few others. A
    # loaded machine drops frames of its own anywhere: with as few as three injected sequences in the take one
    # of them coincided on r0c0 (CI with two CPU hogs beside it: 1 of 3 against 1 in 27 elsewhere), which the
    # earlier rate comparison (injected rate at most the other rate + 0.25) failed. A leak is all of them.
    for name in RIG.camera_names:
        if name == "r1c2":
            continue
        cam = take.manifest.cameras[name]
        span = set(range(max(cam.first_sequence, r1c2.first_sequence) + 1, min(cam.last_sequence, r1c2.last_sequence)))
        inj = injected & span
        own = set(cam.source_drops) & span
        if not inj:
            continue
        hit_other = len(own - inj) / max(1, len(span - inj))
        assert not inj <= own or hit_other >= 0.5, (name, sorted(inj), sorted(own))


def test_preflight_failure_blocks_recording_and_says_why(fast_out: Path) -> None:
    tmp_path = fast_out
    app = live_app(tmp_path, ["unlocked=[r0c1]"])

    async def script(pilot: Any) -> None:
        await armed(pilot)
        await pilot.press("r")
        await until(pilot, lambda: isinstance(app.screen, Notice), what="the refusal")
        assert "preflight failed" in app.screen.title_text
        assert any("r0c1: reference not locked" in line for line in app.screen.lines)
        assert not app.session.recording
        await pilot.press("escape")
        await pilot.press("q")

    run(app, script)
    assert not (tmp_path / "S01-01-T01").exists()


def test_q_quits_from_a_refusal(fast_out: Path) -> None:
    """#13: after a refused r, q left the UI open however often it was pressed. The refusal is a modal screen,
    and Textual gives a modal screen's keys to that screen only: the app's q never ran. Now q on the refusal
    quits (nothing is recording, so it does not ask)."""
    app = live_app(fast_out, ["unlocked=[r0c1]"])

    async def script(pilot: Any) -> None:
        await armed(pilot)
        await pilot.press("r")
        await until(pilot, lambda: isinstance(app.screen, Refused), what="the refusal")
        await pilot.press("q")
        await until(pilot, lambda: not app.is_running, timeout=30, what="q to quit from the refusal")

    run(app, script)
    assert app.session is None  # closed: cameras and tally released
    assert not (fast_out / "S01-01-T01").exists()


def test_quitting_while_recording_asks_first(fast_out: Path) -> None:
    tmp_path = fast_out
    app = live_app(tmp_path)

    async def script(pilot: Any) -> None:
        await armed(pilot)
        await pilot.press("r")
        await until(pilot, lambda: app.session.recording, what="recording")
        await pilot.press("q")
        await until(pilot, lambda: isinstance(app.screen, Confirm), what="the question")
        await pilot.press("n")
        await pilot.pause(0.3)
        assert app.session.recording and app.is_running  # still recording
        await pilot.press("q")
        await until(pilot, lambda: isinstance(app.screen, Confirm), what="the question again")
        await pilot.press("y")

    run(app, script)
    take = TakeReader(tmp_path / "S01-01-T01")  # quitting kept what was recorded
    assert take.status in ("ended", "complete") and len(take.complete_sets()) > 0


def test_a_stalled_ui_drops_no_frame(fast_out: Path) -> None:
    tmp_path = fast_out
    app = live_app(tmp_path)
    stall: list[tuple[int, int]] = []

    async def script(pilot: Any) -> None:
        await armed(pilot)
        stall.append(await record(pilot, 1.0, stall_s=0.6))
        await pilot.press("q")

    run(app, script)
    take = TakeReader(tmp_path / "S01-01-T01")
    (t0, t1), period = stall[0], int(take.manifest.timing.frame_period_ns or 0)
    # capture goes on while the UI is stuck: every camera has a frame for each instant of the stall (a reader
    # held up by the UI would lose the oldest of them once the device's 8 buffers overflow, after 0.32 s).
    # One missing frame per camera is allowed for a shared machine's own hiccups.
    instants = (t1 - t0) // period
    for name in take.names:
        captured = take.index[name]["capture_ns"].astype(np.int64)
        inside = int(((captured >= t0) & (captured < t1)).sum())
        assert inside >= instants - 1, (name, inside, instants)
        cam = take.manifest.cameras[name]
        assert not cam.writer_drops and not cam.not_written, name
    assert len(take.complete_sets()) >= 30  # 1.6 s of 25 fps, the stall included


def test_keys_for_devices_the_rig_lacks_are_not_offered(tmp_path: Path) -> None:
    import yaml

    data = yaml.safe_load((Path(__file__).resolve().parents[2] / "rigs" / "sim-3x3.yaml").read_text())
    del data["tally"], data["camera_control"]
    from rigctl.rig import rig_from_dict

    bare = rig_from_dict(data)
    app = ShootApp(snapshot_source=lambda: fixed_snapshot(), rig=bare)

    async def script(pilot: Any) -> None:
        await pilot.pause(0.2)
        assert app.check_action("tally", ()) is None and app.check_action("settings", ()) is None
        assert app.check_action("record", ()) is True

    run(app, script)


def test_log_records_from_threads_go_into_the_ui_and_everything_is_put_back() -> None:
    """A warning logged (or warned) by a capture thread while the UI runs is shown in the UI and never reaches
    the terminal handler the CLI installed; the UI leaves the process's logging, warnings capture and thread
    switch interval as it found them."""
    import io
    import logging
    import sys
    import threading
    import warnings

    terminal = io.StringIO()
    cli_handler = logging.StreamHandler(terminal)  # the CLI's basicConfig handler holds the real stderr like this
    root = logging.getLogger()
    root.addHandler(cli_handler)
    before_handlers, before_switch = list(root.handlers), sys.getswitchinterval()
    app = fixed_app()

    def capture_thread() -> None:
        logging.getLogger("rigctl.capture.recorder").warning("r1c2: writer queue %d %% full", 90)
        warnings.warn("a library complains", RuntimeWarning, stacklevel=1)

    async def script(pilot: Any) -> None:
        await pilot.pause(0.1)
        assert sys.getswitchinterval() == 0.0005
        t = threading.Thread(target=capture_thread)
        t.start()
        t.join()
        await until(pilot, lambda: len(app.log_lines) >= 2, timeout=10, what="the records in the UI")

    try:
        run(app, script)
        assert any("r1c2: writer queue 90 % full" in line for line in app.log_lines), list(app.log_lines)
        assert any("a library complains" in line for line in app.log_lines)
        assert terminal.getvalue() == ""  # nothing was written over the screen
        assert root.handlers == before_handlers and sys.getswitchinterval() == before_switch
        logging.getLogger("rigctl.capture.recorder").warning("after the UI")
        assert "after the UI" in terminal.getvalue()  # the terminal handler is back
    finally:
        root.removeHandler(cli_handler)


# ---- snapshots of the screens, with fixed data --------------------------------------------------------------
def fixed_snapshot() -> Snapshot:
    ramp = np.tile(np.linspace(16, 235, 48, dtype=np.uint8), (27, 1))
    tiles = []
    for i, n in enumerate(RIG.camera_names):
        c = RIG.camera(n)
        state = SettingState.CONFIRMED if i % 2 == 0 else SettingState.UNCONFIRMED
        tiles.append(
            TileStatus(
                n,
                c.row,
                c.col,
                signal=True,
                format="960x540 UYVY 25 fps",
                format_ok=True,
                lock="external, locked",
                locked=True,
                fps=25.0,
                source_drops=2 if n == "r1c2" else 0,
                queue_fill=0.1,
                age_ms=35.0 if n != "r2c0" else 120.0,
                stale=n == "r2c0",
                tally="PGM",
                mb_s=25.9,
                settings={"exposure_us": SettingResult(n, "exposure_us", 10000, state)},
                thumbnail=np.roll(ramp, 4 * i, axis=1),
            )
        )
    return Snapshot(
        rig="sim-3x3",
        tiles=tiles,
        take="S01-01-T03",
        scene="S01",
        shot="01",
        take_number=3,
        recording=True,
        busy="",
        duration_s=12.4,
        timecode="00:00:12:10",
        skew_p50_us=152.0,
        skew_p99_us=230.0,
        disk_free_gb=412.5,
        minutes_left=9.0,
        disk_warning=True,
        planner="subject 1.00 m deep from 1.95 m to 2.95 m; every pair within budget from 3.18 m",
        pair_lights=[("r1c1-r1c2", True), ("r1c1-r2c1", False), ("r1c1-r2c2", False)],
        message="recording S01-01-T03",
    )


def fixed_app() -> ShootApp:
    return ShootApp(snapshot_source=fixed_snapshot, rig=SHIPPED)


def test_snapshot_main_screen(snap_compare: Any) -> None:
    assert snap_compare(fixed_app(), terminal_size=(170, 60))


def test_snapshot_help_screen(snap_compare: Any) -> None:
    assert snap_compare(fixed_app(), press=["question_mark"], terminal_size=(170, 60))


def test_snapshot_planner_screen(snap_compare: Any) -> None:
    assert snap_compare(fixed_app(), press=["p"], terminal_size=(170, 60))


def test_planner_recomputes_as_values_are_typed() -> None:
    app = fixed_app()

    async def script(pilot: Any) -> None:
        await pilot.press("p")
        await until(pilot, lambda: isinstance(app.screen, PlannerScreen), what="the planner")
        plan = app.screen.query_one("#plan")
        before = str(plan.render())
        assert "1.948" in before or "1.95" in before
        app.screen.query_one("#depth").value = "0.5"
        await pilot.pause(0.2)
        after = str(plan.render())
        assert after != before
        app.screen.query_one("#depth").value = "-1"
        await pilot.pause(0.2)
        assert "not a plan" in str(plan.render())
        # the distances `rigctl plan` refuses are refused here too, named as the fields are, not planned into
        # numbers of hundreds of digits
        app.screen.query_one("#depth").value = "1"
        for field, value, says in (
            ("#near", "1e-300", "near 1e-300 m: a plan's distances run from 0.001 m to 1e+06 m"),
            ("#near", "2", None),
            ("#far", "1e300", "far 1e+300 m: a plan's distances run from 0.001 m to 1e+06 m (inf for a background"),
            ("#far", "", None),
            ("#near", "", None),
            ("#depth", "1e9", "subject depth 1e+09 m: at most 1e+06 m"),
            ("#depth", "0.9999999", None),
            ("#far", "1", "far 1 m and subject depth 1 m: the subject's near side would be 1e-07 m from the lens"),
        ):
            app.screen.query_one(field).value = value
            await pilot.pause(0.2)
            text = " ".join(str(plan.render()).split())
            if says is None:
                assert "not a plan" not in text, text
            else:
                assert "not a plan" in text and says in text, text
        await pilot.press("escape")
        await pilot.press("question_mark")
        assert isinstance(app.screen, HelpScreen)

    run(app, script)


# ---- a real terminal ------------------------------------------------------------------------------------------
def tmux(*args: str) -> str:
    return subprocess.run(["tmux", *args], capture_output=True, text=True, check=True).stdout


def test_in_a_real_terminal(tmp_path: Path) -> None:
    assert shutil.which("tmux"), "tmux is needed (.ci/run installs it)"
    name = f"rigctl-tui-{tmp_path.name}"
    cmd = " ".join([*rigctl_exe(), "tui", "--out", str(tmp_path), "--sim", "motion=false"])
    tmux("new-session", "-d", "-s", name, "-x", "200", "-y", "60", cmd)

    def screen() -> str:
        return tmux("capture-pane", "-p", "-t", name)

    def wait_for(text: str, timeout: float = 90.0) -> None:
        t0 = time.monotonic()
        while text not in screen():
            if time.monotonic() - t0 > timeout:
                raise AssertionError(f"{text!r} never appeared:\n{screen()}")
            time.sleep(0.2)

    try:
        wait_for("STANDBY")
        assert "r2c2" in screen() and "r0c0" in screen()
        tmux("send-keys", "-t", name, "r")
        wait_for("REC")
        time.sleep(1.5)
        tmux("send-keys", "-t", name, "r")
        wait_for("take 02")  # the take was written and the next one is up
        tmux("send-keys", "-t", name, "q")
        t0 = time.monotonic()
        while time.monotonic() - t0 < 20:
            alive = subprocess.run(["tmux", "has-session", "-t", name], capture_output=True).returncode == 0
            if not alive:  # q quit the UI, which ended the terminal's session
                break
            time.sleep(0.2)
        else:
            raise AssertionError(f"the UI did not quit:\n{screen()}")
    finally:
        subprocess.run(["tmux", "kill-session", "-t", name], capture_output=True)
    take = TakeReader(tmp_path / "S01-01-T01")
    assert len(take.names) == 9 and len(take.complete_sets()) >= 20


def test_tally_from_the_ui_refuses_what_rigctl_tally_refuses(fast_out: Path) -> None:
    """The tally prompt takes the same state as ``rigctl tally``: a camera named twice or not in the rig is
    refused (the app shows it in a notice), and the state is left as it was."""
    from rigctl.errors import RigctlError

    session = Session(RIG, fast_out, SIM)
    try:
        session.set_tally(["r1c1"], ["r1c0", "r1c2"])
        before = session.tally_state
        for program, preview, fragment in (
            (["r0c0", "r0c0"], [], "program: camera r0c0 is named twice"),
            (["r9c9"], [], "camera 'r9c9' is not in rig"),
        ):
            with pytest.raises(RigctlError, match=fragment):
                session.set_tally(program, preview)
            assert session.tally_state == before
    finally:
        session.close()


def test_quit_while_a_take_is_stopping_finishes_it_once(fast_out: Path) -> None:
    """The stop key's worker and the quit can meet: the take is finalised once, the cameras closed once, and
    the session does not arm again after it was closed."""
    import threading

    session = Session(RIG, fast_out, SIM)
    session.arm()
    session.start()
    time.sleep(0.8)
    errors: list[BaseException] = []

    def stop() -> None:
        try:
            session.stop()
        except BaseException as exc:  # the test reports whatever escaped
            errors.append(exc)

    stopper = threading.Thread(target=stop)
    stopper.start()
    session.close()
    stopper.join(timeout=30)
    assert not stopper.is_alive() and not errors, errors
    assert session.recorder is None and not session.recording
    take = TakeReader(fast_out / "S01-01-T01")
    assert take.status in ("ended", "complete") and len(take.complete_sets()) >= 15


def test_a_restarted_session_numbers_takes_after_those_on_disk(fast_out: Path) -> None:
    """A take recorded by one session is on disk; a new session on the same folder (the UI restarted) starts
    at T02 and records there, not at T01 (which exists: preflight would refuse it forever)."""
    (fast_out / "S01-02-T07").mkdir(parents=True)  # another shot's take does not count
    (fast_out / "S01-01-notes").mkdir()
    first = Session(RIG, fast_out, SIM)
    try:
        assert first.take_name == "S01-01-T01"
        first.arm()
        first.start()
        time.sleep(0.5)
        first.stop()
    finally:
        first.close()
    assert TakeReader(fast_out / "S01-01-T01").status in ("ended", "complete")
    again = Session(RIG, fast_out, SIM)
    try:
        assert again.take_number == 2 and again.take_name == "S01-01-T02"
        again.arm()
        assert again.preflight() == []  # T01 exists, and is not where this take goes
        again.start()
        time.sleep(0.5)
        again.stop()
    finally:
        again.close()
    assert TakeReader(fast_out / "S01-01-T02").status in ("ended", "complete")


def test_the_disk_is_measured_before_the_cameras_stream_not_at_every_take(
    fast_out: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Measured while nine capture threads stream, the test writes wait for the interpreter between blocks
    and the disk reads slow: the session measures once, before the first arming (and again only on m)."""
    import rigctl.tui.session

    session = Session(RIG, fast_out, SIM)
    try:
        session.arm()
        assert session._speeds[fast_out].median_bps > 0

        def no_measuring(folder: Path) -> WriteSpeed:
            raise AssertionError(f"{folder} measured again while the cameras stream")

        monkeypatch.setattr(rigctl.tui.session, "measure_write", no_measuring)
        assert session.preflight() == []
        assert session.last_preflight is not None and session.last_preflight.ok
    finally:
        session.close()


def test_a_refused_take_can_be_measured_again_or_recorded_anyway_after_a_warning(
    fast_out: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A disk far too slow (injected: 1 MB/s) refuses the open-ended take; m measures again (injected: still
    slow) and says so; f asks, stating the risk, and y records anyway. Then q quits at once."""
    import rigctl.tui.session

    slow = WriteSpeed((1e6, 1e6, 1e6))
    measured: list[Path] = []

    def measure(folder: Path) -> WriteSpeed:
        measured.append(folder)
        return slow

    monkeypatch.setattr(rigctl.tui.session, "measure_write", measure)
    app = live_app(fast_out)

    async def script(pilot: Any) -> None:
        await armed(pilot)
        assert measured == [fast_out]
        await pilot.press("r")
        await until(pilot, lambda: isinstance(app.screen, Refused), what="the refusal")
        assert any("far more than it sustains" in line for line in app.screen.lines)
        await pilot.press("m")
        await until(pilot, lambda: len(measured) == 2 and not app.session.busy, what="measuring again")
        assert "median 1 MB/s" in app.session.message
        await pilot.press("r")
        await until(pilot, lambda: isinstance(app.screen, Refused), what="the second refusal")
        await pilot.press("f")
        await until(pilot, lambda: isinstance(app.screen, Confirm), what="the confirmation")
        assert "writer drops" in app.screen.question
        await pilot.press("y")
        await until(pilot, lambda: app.session.recording, what="recording anyway")
        assert "despite preflight" in app.session.message
        await pilot.pause(0.5)
        await pilot.press("r")
        await until(pilot, lambda: not app.session.recording and not app.session.busy, what="the take to end")
        await pilot.press("q")
        await until(pilot, lambda: not app.is_running, what="quitting")

    run(app, script)
    assert TakeReader(fast_out / "S01-01-T01").status in ("ended", "complete")
