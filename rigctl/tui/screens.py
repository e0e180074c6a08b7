"""The shoot UI's other screens: help, a yes/no question, a notice, the preflight refusal with what can be done
from there, one line of input, and the planner. On a modal screen Textual gives keys to that screen only, so
every notice binds q itself: q quits from a notice as it does from the main screen."""

from __future__ import annotations

from typing import Any

from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import ModalScreen, Screen
from textual.widgets import Input, Static

from rigctl.errors import RigctlError
from rigctl.planning.planner import check_derived_near, check_distances
from rigctl.planning.report import plan_rig
from rigctl.planning.text import format_plan

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
    # q quits from here as from the main screen (a modal screen's keys never reach the app's bindings)
    BINDINGS = [Binding("escape,enter,space", "dismiss", "close"), Binding("q", "app.quit_app", "quit")]
    DEFAULT_CSS = (
        "Notice { align: center middle; } #notice { width: 90; height: auto; border: thick $warning; padding: 1 2; }"
    )

    def __init__(self, title: str, lines: list[str]) -> None:
        super().__init__()
        self.title_text = title
        self.lines = lines

    def compose(self) -> ComposeResult:
        body = "\n".join(f"  • {line}" for line in self.lines)
        yield Static(f"[b]{self.title_text}[/b]\n\n{body}\n\n(escape closes, q quits)", id="notice")


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
        yield Static(f"[b]{self.title_text}[/b]\n\n{body}\n\n{keys}[b]escape[/b] closes   [b]q[/b] quits", id="notice")

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
        def num(widget_id: str) -> float | None:
            raw = self.query_one(f"#{widget_id}", Input).value.strip()
            return float(raw) if raw else None

        out = self.query_one("#plan", Static)
        try:
            depth, near, far = num("depth"), num("near"), num("far")
            check_distances(near, far, depth)  # the distances `rigctl plan` accepts, named as the fields are
            plan = plan_rig(self.rig, subject_depth_m=depth, near_m=near, far_m=far, budget_fraction=num("budget"))
            given = " and ".join(f"{n} {v:g} m" for n, v in (("far", far), ("subject depth", depth)) if v is not None)
            check_derived_near(plan.near_m, given or "the rig file plan section", "a deeper subject, or near and far")
            out.update(Text(format_plan(plan, self.rig)))
        except (ValueError, RigctlError) as exc:
            out.update(Text(f"not a plan: {exc}", style="bold red"))
