"""Every ``--help`` teaches: it ends with an ``examples:`` section, leaks no formatting (``%%``, ``%(``), and
every example is a command line the parser accepts as written (tests/integration/test_cli_examples.py runs
the cheap ones)."""

from __future__ import annotations

import argparse
import re
import shlex

import pytest
from cli_help_support import ALL, example_lines

from rigctl.cli.main import build_parser


def test_the_tree_has_every_command_and_subcommand() -> None:
    names = {name for name, _ in ALL}
    assert {"rigctl", "rigctl take export", "rigctl bench depth", "rigctl miv ivpsnr", "rigctl completion"} <= names
    assert len(names) >= 28


@pytest.mark.parametrize(("name", "parser"), ALL, ids=[n for n, _ in ALL])
def test_every_help_ends_with_examples_and_leaks_no_formatting(name: str, parser: argparse.ArgumentParser) -> None:
    text = parser.format_help()
    assert "%%" not in text and "%(" not in text, text
    assert "\nexamples:\n" in text, f"{name} --help has no examples section"
    # the examples section is the last one: nothing after it but its own indented lines
    tail = text.split("\nexamples:\n", 1)[1]
    assert all(ln.startswith("  ") for ln in tail.splitlines() if ln.strip()), tail
    commands = example_lines(text)
    assert len(commands) >= 2 or name == "rigctl completion", commands
    # a command's examples are about that command (the root's name any)
    own = [c for c in commands if c.startswith(name + " ")]
    assert own or name == "rigctl", commands


def _argv(command: str) -> list[str] | None:
    """The rigctl arguments of an example line, up to a redirection or pipe; None for shell around it."""
    words = shlex.split(command)
    if not words or words[0] != "rigctl":
        return None
    for i, w in enumerate(words):
        if w in (">", ">>", "|", "&&", ";"):
            return words[1:i]
    return words[1:]


EXAMPLES = sorted({c for _, p in ALL for c in example_lines(p.format_help())})


@pytest.mark.parametrize("command", EXAMPLES)
def test_every_example_is_a_command_line_the_parser_accepts(command: str) -> None:
    argv = _argv(command)
    if argv is None:  # shell around rigctl (source <(rigctl completion bash)): its inner command
        inner = re.search(r"rigctl [^)]*", command)
        assert inner is not None, command
        argv = shlex.split(inner[0])[1:]
    parser = build_parser()
    try:
        ns = parser.parse_args(argv)
    except SystemExit as exc:  # --help exits 0; a refused line exits 2
        assert exc.code == 0, command
        return
    assert getattr(ns, "func", None) is not None, command


def test_help_is_coloured_only_where_the_reader_is_a_terminal() -> None:
    """rich-argparse decides from the stream: a pipe gets plain text (what the tests above read)."""
    text = dict(ALL)["rigctl board"].format_help()
    assert "\x1b[" not in text and "100 % scale" in text
