"""The one progress display (rigctl/cli/progress.py): a rich bar with count, rate, elapsed and time remaining
on a terminal; one summary line elsewhere, only for work that finished; nothing with --quiet."""

from __future__ import annotations

import io

import pytest

from rigctl.cli.progress import Progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_off_a_terminal_one_summary_line_with_count_time_and_rate() -> None:
    now = [100.0]
    out = io.StringIO()
    with Progress("exporting T1", "frame sets", stream=out, clock=lambda: now[0]) as bar:
        for k in range(1, 5):
            bar.steps(k, 4)
            assert out.getvalue() == ""  # nothing while it runs
        now[0] = 108.0
    assert out.getvalue() == "exporting T1: 4 of 4 frame sets in 8.0 s (0.50 frame sets/s)\n"


def test_no_summary_for_work_that_raised_and_none_when_quiet() -> None:
    out = io.StringIO()
    with pytest.raises(RuntimeError), Progress("depth T1", "cameras", stream=out) as bar:
        bar.update(3, 9)
        raise RuntimeError("the command's one error line is all the user sees")
    assert out.getvalue() == ""
    with Progress("depth T1", "cameras", quiet=True, stream=out) as bar:
        bar.update(9, 9)
    assert out.getvalue() == ""


def test_a_share_of_known_length_is_counted_in_items() -> None:
    out = io.StringIO()
    with Progress("recording T1", "frame sets", total=50, stream=out, clock=lambda: 0.0) as bar:
        bar.fraction(0.5)
        assert (bar.done, bar.total) == (25, 50)
        bar.fraction(1.0)
    assert out.getvalue().startswith("recording T1: 50 of 50 frame sets in ")


def test_on_a_terminal_a_bar_with_count_rate_elapsed_and_time_left() -> None:
    term = Terminal()
    with Progress("render T1", "views", stream=term) as bar:
        for k in range(5):
            bar.update(k, 4, f"view {k}")
    text = term.getvalue()
    assert "render T1" in text and "4/4 views" in text and "elapsed" in text and "left" in text, text
    assert "render T1: 4 of 4" not in text  # the bar, not the summary line


def test_a_second_pass_starts_the_count_again_and_the_summary_tells_the_passes_apart() -> None:
    """``depth`` and ``process`` compute every frame set again when the take's range was widened: the count
    starts again (the take's frame sets, not the take's times the passes), and the summary says the rest."""
    now = [0.0]
    out = io.StringIO()
    with Progress("process T1", "frame sets", stream=out, clock=lambda: now[0]) as bar:
        for k in range(7):
            bar.update(k, 6)
        for k in range(7):
            bar.update(k, 6, "round 2: the take's range was widened")
        now[0] = 6.0
    assert out.getvalue() == "process T1: 6 of 6 frame sets (and 6 in earlier passes) in 6.0 s (2.00 frame sets/s)\n"
    term = Terminal()
    with Progress("process T1", "frame sets", stream=term) as bar:
        for k in range(7):
            bar.update(k, 6)
        bar.update(0, 6, "round 2: the take's range was widened")
        bar.update(3, 6)
        assert bar._task is not None and bar._bar is not None
        task = bar._bar.tasks[0]
        assert (task.completed, task.total, task.fields["what"]) == (3, 6, "round 2: the take's range was widened")
        assert task.speed is None or task.speed >= 0  # no rate or time left from a count that ran backwards
    assert "round 2" in term.getvalue()  # what is done, cut to the line
