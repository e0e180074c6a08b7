"""``rigctl tui``: the shoot at a glance. Camera tiles laid out like the rig (seen from behind), a global bar,
one key to record. Device I/O runs in worker threads; the screen gets coalesced snapshots by message and
never holds up capture (a stalled screen only shows older numbers)."""

from __future__ import annotations

import collections
import logging
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from textual import work
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Grid
from textual.message import Message
from textual.widgets import Footer, Static

from rigctl.errors import PreflightError, RigctlError
from rigctl.tui.logs import LogRecordPosted, RoutedLogging
from rigctl.tui.screens import FORCE_RISK, Ask, Confirm, HelpScreen, Notice, PlannerScreen, Refused
from rigctl.tui.session import Session, Snapshot
from rigctl.tui.tiles import CameraTile, GlobalBar

log = logging.getLogger(__name__)


class SnapshotReady(Message):
    """A new snapshot is waiting (coalesced: one message however many snapshots were taken)."""


class ShootApp(App[None]):
    TITLE = "rigctl shoot"
    CSS = "#tiles { grid-gutter: 0 1; height: 1fr; }"
    BINDINGS = [
        Binding("r", "record", "record / stop"),
        Binding("q", "quit_app", "quit"),
        Binding("m", "measure", "measure disk"),
        Binding("c", "mark('circled')", "circle"),
        Binding("n", "mark('no-good')", "no-good"),
        Binding("t", "tally", "tally"),
        Binding("s", "settings", "settings"),
        Binding("p", "planner", "planner"),
        Binding("question_mark", "help", "help"),
    ]

    def __init__(
        self,
        session_factory: Callable[[], Session] | None = None,
        snapshot_source: Callable[[], Snapshot] | None = None,
        poll_s: float = 0.25,
        thumbnails: bool = True,
        rig: Any = None,
    ) -> None:
        super().__init__()
        self.session_factory = session_factory
        self.session: Session | None = None
        self.snapshot_source = snapshot_source
        self.poll_s = poll_s
        self.thumbnails = thumbnails
        self.rig = rig
        self._latest: Snapshot | None = None
        self._pending = threading.Event()
        self._stop = threading.Event()
        self.snapshots_shown = 0
        self.log_lines: collections.deque[str] = collections.deque(maxlen=200)  # what the log handler posted
        self._routed: RoutedLogging | None = None
        self._switch_interval = sys.getswitchinterval()

    def compose(self) -> ComposeResult:
        yield GlobalBar(id="bar")
        yield Grid(id="tiles")
        yield Footer()

    def on_mount(self) -> None:
        # capture threads must get the interpreter within a fraction of a frame period even while the screen
        # redraws (Python's default hand-over is every 5 ms, and only when the holder allows it)
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(0.0005)
        self._routed = RoutedLogging.install(self.post_message)
        if self.snapshot_source is not None:  # a fixed picture (snapshot tests of the layout)
            self._latest = self.snapshot_source()
            self._show()
            return
        self.query_one(GlobalBar).update("opening the rig's cameras ...")
        self.start_session()

    @work(thread=True, exclusive=True, group="session")
    def start_session(self) -> None:
        assert self.session_factory is not None
        try:
            self.session = self.session_factory()
            self.rig = self.session.rig
            self.session.arm()
        except RigctlError as exc:
            log.info("opening the session: %s", exc)  # on screen already: in the bar, not as a notification
            if self.session is not None:
                self.session.message = f"cannot stream: {exc}"
            else:
                self.call_from_thread(self.query_one(GlobalBar).update, f"cannot open the rig: {exc}")
                return
        self._poll()

    def _poll(self) -> None:
        """Runs in the session worker: snapshots at a steady rate, one pending message at most."""
        while not self._stop.is_set():
            session = self.session
            if session is None:
                return
            try:
                self._latest = session.snapshot()
            except RigctlError as exc:
                session.message = str(exc)
            if not self._pending.is_set():
                self._pending.set()
                self.post_message(SnapshotReady())
            time.sleep(self.poll_s)

    def on_snapshot_ready(self, _: SnapshotReady) -> None:
        self._pending.clear()
        self._show()

    def _show(self) -> None:
        snap = self._latest
        if snap is None:
            return
        grid = self.query_one("#tiles", Grid)
        if not grid.children:
            rows = max(t.row for t in snap.tiles) + 1
            cols = max(t.column for t in snap.tiles) + 1
            grid.styles.grid_size_columns = cols
            grid.styles.grid_size_rows = rows
            by_pos = {(t.row, t.column): t for t in snap.tiles}
            for r in range(rows):
                for c in range(cols):
                    t = by_pos.get((r, c))
                    grid.mount(CameraTile(t.name, self.thumbnails) if t else Static(""))
        for t in snap.tiles:
            self.query_one(f"#tile-{t.name}", CameraTile).show(t, snap.recording)
        self.query_one(GlobalBar).show(snap)
        self.snapshots_shown += 1

    # ---- actions ------------------------------------------------------------------------------------------
    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        """Keys for devices the rig does not have are not shown."""
        rig = self.session.rig if self.session else self.rig
        if rig is not None and action == "tally" and rig.model.tally is None:
            return None
        if rig is not None and action == "settings" and rig.model.camera_control is None:
            return None
        return True

    def action_record(self) -> None:
        s = self.session
        if s is None or s.busy:
            return
        if s.recording:
            self.stop_take()
        else:
            self.start_take()

    @work(thread=True, exclusive=True, group="take")
    def start_take(self, force: bool = False) -> None:
        session = self.session
        if session is None:
            return
        try:
            session.start(force=force)
        except PreflightError as exc:
            log.info("recording refused: %s", exc)
            self.call_from_thread(self.push_screen, Refused(exc.problems, exc.forcible), self._after_refusal)
        except RigctlError as exc:
            self.call_from_thread(self.push_screen, Notice("Recording refused", [str(exc)]))

    def _after_refusal(self, choice: str | None) -> None:
        if choice == "measure":
            self.action_measure()
        elif choice == "force":

            def answer(yes: bool | None) -> None:
                if yes and self.session is not None and not self.session.recording:
                    self.start_take(force=True)

            self.push_screen(Confirm(FORCE_RISK), answer)

    def action_measure(self) -> None:
        s = self.session
        if s is None or s.busy or s.recording:
            return
        self.measure_disk()

    @work(thread=True, exclusive=True, group="take")
    def measure_disk(self) -> None:
        session = self.session
        if session is None:
            return
        session.busy = "measuring"
        try:
            session.measure()
        finally:
            session.busy = ""

    @work(thread=True, exclusive=True, group="take")
    def stop_take(self) -> None:
        session = self.session
        assert session is not None
        try:
            session.stop()
        except Exception as exc:  # the crew must see it; the session has left the recording state
            lines = [session.message, f"{type(exc).__name__}: {exc}"]
            self.call_from_thread(self.push_screen, Notice("The take did not finish cleanly", lines))

    def action_quit_app(self) -> None:
        if self.session is not None and self.session.recording:

            def answer(yes: bool | None) -> None:
                if yes:
                    self._close_and_exit()

            self.push_screen(Confirm("A take is recording. Stop it, keep what was recorded, and quit?"), answer)
            return
        self._close_and_exit()

    def _close_and_exit(self) -> None:
        self._close_session()
        self.exit()

    def _close_session(self) -> None:
        self._stop.set()
        session, self.session = self.session, None
        if session is not None:
            session.close()  # a take still recording is stopped and finalised, never lost

    def on_unmount(self) -> None:
        self._close_session()
        if self._routed is not None:  # the process gets back the logging and the switch interval it had
            self._routed.restore()
            self._routed = None
        sys.setswitchinterval(self._switch_interval)

    def on_log_record_posted(self, record: LogRecordPosted) -> None:
        self.log_lines.append(record.text)
        if record.level >= logging.WARNING:
            self.notify(record.text, severity="error" if record.level >= logging.ERROR else "warning", timeout=10)

    def action_help(self) -> None:
        self.push_screen(HelpScreen())

    def action_planner(self) -> None:
        rig = self.session.rig if self.session else self.rig
        if rig is not None:
            self.push_screen(PlannerScreen(rig))

    def action_mark(self, verdict: str) -> None:
        def done(note: str | None) -> None:
            if note is None or self.session is None:
                return
            try:
                self.session.mark(verdict, note)
            except RigctlError as exc:
                self.push_screen(Notice("Cannot mark the take", [str(exc)]))

        self.push_screen(Ask(f"Mark the last take {verdict}: note (enter to save, escape to cancel)"), done)

    def action_tally(self) -> None:
        def done(text: str | None) -> None:
            if not text or self.session is None:
                return
            program, _, preview = text.partition("/")
            try:
                self.session.set_tally(program.split(), preview.split())
            except RigctlError as exc:
                self.push_screen(Notice("Tally not set", [str(exc)]))

        self.push_screen(Ask("Tally: program cameras / preview cameras", "r1c1 / r0c0 r0c1"), done)

    def action_settings(self) -> None:
        def done(text: str | None) -> None:
            if not text or self.session is None:
                return
            values: dict[str, float | str] = {}
            for part in text.split():
                key, _, raw = part.partition("=")
                try:
                    values[key] = float(raw)
                except ValueError:
                    values[key] = raw
            self.apply_settings(values)

        if self.session is not None and self.session.rig.model.camera_control is None:
            self.push_screen(Notice("No camera control", ["this rig has no camera_control section"]))
            return
        self.push_screen(Ask("Camera settings for every camera", "exposure_us=10000 gain=2 white_balance_k=5600"), done)

    @work(thread=True, group="control")
    def apply_settings(self, values: dict[str, float | str]) -> None:
        assert self.session is not None
        try:
            self.session.apply_settings(values)
        except RigctlError as exc:
            self.call_from_thread(self.push_screen, Notice("Camera settings not applied", [str(exc)]))
