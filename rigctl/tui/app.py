"""``rigctl tui``: the shoot at a glance. Camera tiles laid out like the rig (seen from behind), a global bar,
one key to record. Device I/O runs in worker threads; the screen gets coalesced snapshots by message and
never holds up capture (a stalled screen only shows older numbers)."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from rich.text import Text
from textual import on, work
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Vertical
from textual.message import Message
from textual.screen import ModalScreen, Screen
from textual.widgets import Footer, Input, Static

from rigctl.errors import RigctlError
from rigctl.interfaces import SettingState
from rigctl.preflight import PreflightError
from rigctl.tui.session import Session, Snapshot, TileStatus

KEYS = [
    ("r", "start / stop recording on every camera"),
    ("q", "quit (asks first while recording)"),
    ("m", "measure the destination's write speed again (preflight uses the new figure)"),
    ("c", "mark the last take circled, with a note"),
    ("n", "mark the last take no-good, with a note"),
    ("t", "set tally: program and preview cameras"),
    ("s", "apply camera settings to every camera (exposure_us=N gain=N white_balance_k=N ...)"),
    ("p", "planner: near/far limits and pair budgets, recomputed as you type"),
    ("question_mark", "this help"),
]


def thumbnail_text(img: Any, width: int = 24) -> Text:
    """A greyscale image in terminal cells: two pixels per cell with the upper half block."""
    text = Text()
    if img is None or not isinstance(img, np.ndarray) or img.ndim != 2 or img.size == 0:
        return Text("(no picture)", style="dim")
    h, w = img.shape
    xs = np.linspace(0, w - 1, width).astype(int)
    rows = max(2, min(12, round(width * h / w / 2) * 2))
    ys = np.linspace(0, h - 1, rows).astype(int)
    small = np.clip((img[np.ix_(ys, xs)].astype(np.float32) - 16) * (255 / 219), 0, 255).astype(int)
    for r in range(0, rows - 1, 2):
        for c in range(width):
            top, bottom = small[r, c], small[r + 1, c]
            text.append("▀", style=f"rgb({top},{top},{top}) on rgb({bottom},{bottom},{bottom})")
        text.append("\n")
    return text


class CameraTile(Static):
    DEFAULT_CSS = """
    CameraTile { border: round $primary; padding: 0 1; height: 100%; width: 100%; }
    CameraTile.recording { border: round red; }
    CameraTile.problem { border: heavy $warning; }
    """

    def __init__(self, name: str, thumbnails: bool = True) -> None:
        super().__init__(id=f"tile-{name}")
        self.camera = name
        self.thumbnails = thumbnails
        self.last: TileStatus | None = None
        self._thumb: Text | None = None
        self._thumb_t = 0.0

    def show(self, t: TileStatus, recording: bool) -> None:
        self.last = t
        text = Text()
        tally_style = "bold white on red" if t.tally == "PGM" else "bold black on green" if t.tally == "PVW" else "dim"
        text.append(f"{t.name} ", style="bold")
        text.append(f" {t.tally or 'no tally'} ", style=tally_style)
        text.append("\n")
        text.append("signal " if t.signal else "NO SIGNAL ", style="green" if t.signal else "bold red")
        text.append(t.format, style="" if t.format_ok else "bold yellow")
        text.append("\n")
        lock_style = "green" if t.locked else "bold red" if t.locked is False else "dim"
        text.append(f"ref {t.lock}\n", style=lock_style)
        text.append(f"{t.fps:5.2f} fps  ")
        age = "-" if t.age_ms is None else f"{t.age_ms:4.0f} ms"
        text.append(f"last {age}\n", style="bold red" if t.stale else "")
        drops = t.source_drops + t.writer_drops
        text.append(
            f"drops src {t.source_drops} wr {t.writer_drops}\n",
            style="bold red" if drops else "green" if recording else "",
        )
        text.append(f"queue {t.queue_fill:4.0%}  {t.mb_s:6.1f} MB/s\n", style="yellow" if t.queue_fill > 0.5 else "")
        if t.drop_in_s is not None:
            text.append(f"falling behind: drops in ~{t.drop_in_s:.0f} s\n", style="bold red")
        for key, result in t.settings.items():
            confirmed = result.state is SettingState.CONFIRMED
            text.append(f"{key} {result.requested} {result.state}\n", style="green" if confirmed else "yellow")
        if self.thumbnails:
            now = time.monotonic()
            if self._thumb is None or now - self._thumb_t >= 1.0:
                self._thumb, self._thumb_t = thumbnail_text(t.thumbnail), now
            text.append_text(self._thumb)
        self.update(text)
        self.set_class(recording, "recording")
        behind = t.drop_in_s is not None
        self.set_class(
            not t.signal or t.stale or not t.format_ok or t.locked is False or drops > 0 or behind, "problem"
        )


class GlobalBar(Static):
    DEFAULT_CSS = "GlobalBar { height: 5; background: $boost; padding: 0 1; }"

    def show(self, s: Snapshot) -> None:
        text = Text()
        text.append(f"{s.rig}  scene {s.scene}  shot {s.shot}  take {s.take_number:02d} ({s.take})  ", style="bold")
        if s.busy:
            text.append(f" {s.busy.upper()} ", style="bold black on yellow")
        elif s.recording:
            text.append(" ● REC ", style="bold white on red")
        else:
            text.append(" STANDBY ", style="bold black on green")
        text.append(f"  {s.duration_s:6.1f} s  TC {s.timecode}\n")
        skew = "-" if s.skew_p50_us is None else f"{s.skew_p50_us:.0f} / {s.skew_p99_us:.0f} us"
        text.append(f"skew p50/p99 {skew}   ")
        if s.disk_free_gb is not None:
            left = "-" if s.minutes_left is None else f"{s.minutes_left:.0f} min"
            text.append(f"disk {s.disk_free_gb:.1f} GB free, {left} left", style="bold red" if s.disk_warning else "")
        text.append("\n")
        text.append(f"plan: {s.planner}  pairs ")
        for _pair, ok in s.pair_lights:
            text.append("●", style="green" if ok else "red")
        text.append("\n")
        text.append(s.message, style="italic")
        self.update(text)


class SnapshotReady(Message):
    """A new snapshot is waiting (coalesced: one message however many snapshots were taken)."""


class HelpScreen(ModalScreen[None]):
    BINDINGS = [Binding("escape,question_mark,q", "dismiss", "close")]
    DEFAULT_CSS = (
        "HelpScreen { align: center middle; } #help { width: 80; height: auto; border: round $accent; padding: 1 2; }"
    )

    def compose(self) -> ComposeResult:
        lines = ["[b]rigctl shoot UI: keys[/b]", ""]
        lines += [f"  [b]{'?' if k == 'question_mark' else k}[/b]  {what}" for k, what in KEYS]
        lines += [
            "",
            "Tiles turn yellow on any problem: no signal, wrong format, reference unlocked,",
            "drops, or a last frame older than two frame periods (shown red).",
            "",
            "escape closes",
        ]
        yield Static("\n".join(lines), id="help")


class Confirm(ModalScreen[bool]):
    BINDINGS = [Binding("y", "yes", "yes"), Binding("n,escape", "no", "no")]
    DEFAULT_CSS = """
    Confirm { align: center middle; }
    #ask { width: 70; height: auto; border: thick red; padding: 1 2; }
    """

    def __init__(self, question: str) -> None:
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        yield Static(f"{self.question}\n\n[b]y[/b] yes   [b]n[/b] no", id="ask")

    def action_yes(self) -> None:
        self.dismiss(True)

    def action_no(self) -> None:
        self.dismiss(False)


class Notice(ModalScreen[str | None]):
    BINDINGS = [Binding("escape,enter,space", "dismiss", "close")]
    DEFAULT_CSS = (
        "Notice { align: center middle; } #notice { width: 90; height: auto; border: thick $warning; padding: 1 2; }"
    )

    def __init__(self, title: str, lines: list[str]) -> None:
        super().__init__()
        self.title_text = title
        self.lines = lines

    def compose(self) -> ComposeResult:
        body = "\n".join(f"  • {line}" for line in self.lines)
        yield Static(f"[b]{self.title_text}[/b]\n\n{body}\n\n(escape closes)", id="notice")


class Refused(Notice):
    """Preflight refused the take: the reasons, and what can be done about them from here."""

    BINDINGS = [
        Binding("escape,enter,space", "dismiss", "close"),
        Binding("f", "choose('force')", "record anyway"),
        Binding("m", "choose('measure')", "measure again"),
    ]

    def __init__(self, lines: list[str], forcible: bool) -> None:
        super().__init__("Recording refused: preflight failed", lines)
        self.forcible = forcible

    def compose(self) -> ComposeResult:
        body = "\n".join(f"  • {line}" for line in self.lines)
        keys = "[b]m[/b] measure the disk again   "
        if self.forcible:
            keys += "[b]f[/b] record anyway (asks first)   "
        yield Static(f"[b]{self.title_text}[/b]\n\n{body}\n\n{keys}[b]escape[/b] closes", id="notice")

    def action_choose(self, what: str) -> None:
        if what == "force" and not self.forcible:
            return
        self.dismiss(what)


FORCE_RISK = (
    "Record anyway? Preflight says this destination cannot keep up (or has too little room): frames the disk "
    "cannot take in time are dropped and counted as writer drops, and a full disk ends the take. The take "
    "itself stays readable."
)


class Ask(ModalScreen[str | None]):
    """One line of input."""

    BINDINGS = [Binding("escape", "cancel", "cancel")]
    DEFAULT_CSS = """
    Ask { align: center middle; }
    #box { width: 90; height: auto; border: round $accent; padding: 1 2; }
    """

    def __init__(self, prompt: str, placeholder: str = "") -> None:
        super().__init__()
        self.prompt = prompt
        self.placeholder = placeholder

    def compose(self) -> ComposeResult:
        with Vertical(id="box"):
            yield Static(self.prompt)
            yield Input(placeholder=self.placeholder, id="answer")

    @on(Input.Submitted)
    def submitted(self, event: Input.Submitted) -> None:
        self.dismiss(event.value)

    def action_cancel(self) -> None:
        self.dismiss(None)


class PlannerScreen(Screen[None]):
    """Equations (1) and (2) for the rig, recomputed as values are typed."""

    BINDINGS = [Binding("escape", "app.pop_screen", "back")]
    DEFAULT_CSS = "PlannerScreen Input { width: 30; } #plan { padding: 1 2; }"

    def __init__(self, session_rig: Any) -> None:
        super().__init__()
        self.rig = session_rig

    def compose(self) -> ComposeResult:
        yield Static("[b]planner[/b]  subject depth (m), near (m), far (m), budget (fraction); escape returns")
        yield Input(value="1.0", id="depth", placeholder="subject depth m")
        yield Input(value="", id="near", placeholder="near m (empty: solve)")
        yield Input(value="", id="far", placeholder="far m (empty: near + depth)")
        yield Input(value="0.04", id="budget", placeholder="budget")
        yield Static(id="plan")

    def on_mount(self) -> None:
        self.recompute()

    @on(Input.Changed)
    def changed(self) -> None:
        self.recompute()

    def recompute(self) -> None:
        from rigctl.plan_report import format_plan, plan_rig

        def num(widget_id: str) -> float | None:
            raw = self.query_one(f"#{widget_id}", Input).value.strip()
            return float(raw) if raw else None

        out = self.query_one("#plan", Static)
        try:
            plan = plan_rig(
                self.rig,
                subject_depth_m=num("depth"),
                near_m=num("near"),
                far_m=num("far"),
                budget_fraction=num("budget"),
            )
            out.update(Text(format_plan(plan, self.rig)))
        except (ValueError, RigctlError) as exc:
            out.update(Text(f"not a plan: {exc}", style="bold red"))


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

    def compose(self) -> ComposeResult:
        yield GlobalBar(id="bar")
        yield Grid(id="tiles")
        yield Footer()

    def on_mount(self) -> None:
        # capture threads must get the interpreter within a fraction of a frame period even while the screen
        # redraws (Python's default hand-over is every 5 ms, and only when the holder allows it)
        sys.setswitchinterval(0.0005)
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
