"""How every ``--help`` of rigctl looks: rich-argparse's colours on a terminal (plain text otherwise), argparse's
own lower-case headings, descriptions wrapped, and an ``examples:`` section at the end whose lines are kept as
written (they are commands to copy)."""

from __future__ import annotations

from typing import ClassVar

from rich_argparse import RichHelpFormatter


class Verbatim(str):
    """Text a help shows line for line (the examples, the simulator's settings), not wrapped."""


class HelpFormatter(RichHelpFormatter):
    """rich-argparse without its markup (our texts hold ``[min, max]`` and the like, which rich would read as
    tags) and with argparse's headings (``usage:``, ``options:``); :class:`Verbatim` texts keep their lines."""

    group_name_formatter = str
    help_markup = False
    text_markup = False
    styles: ClassVar = {**RichHelpFormatter.styles, "argparse.example": "green", "argparse.comment": "grey50"}
    highlights: ClassVar = [
        *RichHelpFormatter.highlights,
        r"(?m)^ +(?P<comment>#.*)$",
        r"(?m)^ +(?P<example>rigctl\b.*)$",
    ]
    _verbatim = False

    def add_text(self, text):  # type: ignore[no-untyped-def]  # rich-argparse's own signature
        self._verbatim = isinstance(text, Verbatim)
        try:
            super().add_text(text)
        finally:
            self._verbatim = False

    def _rich_fill_text(self, text, width, indent):  # type: ignore[no-untyped-def]
        if not self._verbatim:
            return super()._rich_fill_text(text, width, indent)
        from rich.text import Text

        return Text("\n").join(indent + line for line in text.split()) + "\n\n"


def examples(*pairs: tuple[str, str], before: str = "") -> Verbatim:
    """The ``examples:`` section that ends a command's help: each command with what it does on the line above.
    Every command runs as written on a shipped rig, in a folder where ``rigctl demo`` wrote ``rigctl-demo/`` or
    where the ``rigctl record`` examples wrote ``takes/`` (tests/unit/test_cli_help.py parses them all and
    runs the cheap ones)."""
    lines = [before.rstrip("\n"), ""] if before else []
    lines.append("examples:")
    for what, command in pairs:
        lines += [f"  # {what}", f"  {command}"]
    return Verbatim("\n".join(lines))
