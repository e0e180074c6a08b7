"""The one progress display of every command that runs longer than a second (record, calibrate, rectify, depth,
process, render, take export, bench, demo), built on ``rich.progress``.

On a terminal (stderr a tty): a bar with the items done of the total, the rate, the time elapsed and the time
remaining, and what is being done. Anywhere else (a pipe, a CI log): nothing while it runs and one summary
line at the end, ``LABEL: N of N UNIT in S s (R UNIT/s)``, and only when the work finished (an error is the
command's one line, nothing else). ``--quiet`` silences both. The library layers report through plain
callbacks (``done, total, what``); only this module knows how progress is shown."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from types import TracebackType
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:
    from rich.progress import Progress as RichProgress


def add_quiet(p: argparse.ArgumentParser) -> None:
    """``--quiet`` of every command that shows progress."""
    p.add_argument("--quiet", action="store_true", help="no progress bar on a terminal, no summary line elsewhere")


def _columns(unit: str) -> list[Any]:
    from rich.progress import BarColumn, ProgressColumn, TextColumn
    from rich.table import Column
    from rich.text import Text

    def clock(seconds: float | None) -> str:
        if seconds is None:
            return "-:--"
        s = int(seconds)
        return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"

    class Count(ProgressColumn):
        def render(self, task: Any) -> Text:
            total = "?" if task.total is None else f"{task.total:g}"
            return Text(f"{task.completed:g}/{total} {unit}".rstrip(), style="progress.download")

    class Rate(ProgressColumn):
        def render(self, task: Any) -> Text:
            speed = task.finished_speed or task.speed
            return Text("-/s" if speed is None else f"{speed:.2f}/s", style="progress.data.speed")

    class Times(ProgressColumn):
        def render(self, task: Any) -> Text:
            left = 0.0 if task.finished else task.time_remaining
            return Text(f"{clock(task.elapsed)} elapsed, {clock(left)} left", style="progress.remaining")

    class What(ProgressColumn):  # what is being done: the column cut short when the line is too long
        def render(self, task: Any) -> Text:
            return Text(task.fields["what"], style="progress.elapsed", no_wrap=True, overflow="ellipsis")

    def fixed() -> Column:
        return Column(no_wrap=True)

    return [
        TextColumn("{task.description}", table_column=fixed()), BarColumn(bar_width=12, table_column=fixed()),
        Count(table_column=fixed()), Rate(table_column=fixed()), Times(table_column=fixed()),
        What(table_column=Column(overflow="ellipsis")),
    ]  # fmt: skip


class Progress:
    """Progress of one piece of work: ``update(done, total, what)`` as it goes (``total`` None: not known),
    ``close()`` at the end (or use it as a context manager: no summary when the work raised)."""

    def __init__(
        self,
        label: str,
        unit: str = "",
        quiet: bool = False,
        total: int | None = None,
        stream: TextIO | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.label, self.unit, self.quiet = label, unit, quiet
        self.stream = sys.stderr if stream is None else stream
        self.live = not quiet and self.stream.isatty()
        self.clock = clock
        self.started = clock()
        self.done, self.what = 0, ""
        self.earlier = 0  # items counted by earlier passes over the work (see :meth:`update`)
        self.total = total
        self._bar: RichProgress | None = None
        self._task: Any = None
        self._closed = False

    def update(self, done: int, total: int | None = None, what: str = "") -> None:
        """``done`` items of ``total`` (keeps the last total when None), doing ``what``. A count lower than the
        last one starts a new pass over the work (``depth`` and ``process`` run every frame set again when the
        take's range was widened): the bar starts again, its rate and time left this pass's, not a count that
        ran backwards; the summary tells the earlier passes' items apart."""
        changed = done != self.done
        again = done < self.done
        if again:
            self.earlier += self.done
        self.done, self.what = done, what or self.what
        if total is not None:
            self.total = total
        if not self.live or self._closed:
            return
        if again and self._bar is not None:
            self._bar.reset(self._task, total=self.total, completed=done, what=self.what)
        if self._bar is None:
            from rich.console import Console
            from rich.progress import Progress as RichProgress

            self._bar = RichProgress(*_columns(self.unit), console=Console(file=self.stream), transient=False)
            self._bar.start()
            self._task = self._bar.add_task(self.label, total=self.total, what=self.what)
        self._bar.update(self._task, completed=done, total=self.total, what=self.what, refresh=changed)

    def steps(self, done: int, total: int) -> None:
        """The ``(done, total)`` callback of take export and rectify."""
        self.update(done, total)

    def fraction(self, share: float, what: str = "") -> None:
        """For work that reports a share of its length: as items of the total when one is known."""
        total = self.total if self.total is not None else 100
        self.update(round(max(0.0, min(1.0, share)) * total), total, what)

    def summary(self) -> str:
        """The line a run that is not on a terminal ends with."""
        seconds = self.clock() - self.started
        unit = f" {self.unit}" if self.unit else ""
        if self.total is None and not self.done:  # open-ended work that counted nothing (a take until Ctrl-C)
            return f"{self.label}: finished in {seconds:.1f} s"
        of = f"{self.done} of {self.total}" if self.total is not None else f"{self.done}"
        items = self.done + self.earlier
        rate = f" ({items / seconds:.2f}{unit}/s)" if seconds > 0 and items else ""
        again = f" (and {self.earlier} in earlier passes)" if self.earlier else ""
        return f"{self.label}: {of}{unit}{again} in {seconds:.1f} s{rate}"

    def close(self, finished: bool = True) -> None:
        """Stop the bar (it stays on the terminal as it last was), or print the summary line when the work
        ``finished`` and the bar was not on a terminal."""
        if self._closed:
            return
        self._closed = True
        if self._bar is not None:
            if finished and self.total is not None:
                self._bar.update(self._task, completed=self.done, total=self.total)
            self._bar.stop()
        elif finished and not self.quiet and not self.live:
            print(self.summary(), file=self.stream, flush=True)

    def __enter__(self) -> Progress:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(finished=kind is None)
