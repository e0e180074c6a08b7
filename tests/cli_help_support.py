"""The command line's parsers and the examples their help gives (tests/unit/test_cli_help.py checks them all,
tests/integration/test_cli_examples.py runs the cheap ones)."""

from __future__ import annotations

import argparse

from rigctl.cli.main import build_parser


def parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> list[tuple[str, argparse.ArgumentParser]]:
    """The whole tree: the root, every command and every subcommand, with its command path."""
    found = [(" ".join(("rigctl", *path)), parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += parsers(sub, (*path, name))
    return found


ALL = parsers(build_parser())


def example_lines(text: str) -> list[str]:
    """The commands of a help's examples section (comment lines left out)."""
    section = text.split("\nexamples:\n", 1)[1]
    return [ln.strip() for ln in section.splitlines() if ln.strip() and not ln.strip().startswith("#")]
