"""The shoot UI's main-screen widgets: a camera tile (signal, format, reference, rate, drops, queue, settings,
a thumbnail in terminal cells) and the global bar (take, recording state, timecode, skew, disk, plan)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from rich.text import Text
from textual.widgets import Static

from rigctl.interfaces import SettingState
from rigctl.tui.session import Snapshot, TileStatus


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
