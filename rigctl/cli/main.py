"""Entry point of the ``rigctl`` console script.

Every error a user can cause is a :class:`~rigctl.errors.RigctlError`: it becomes one line on stderr and
a non-zero exit code. ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import os

# OpenBLAS's threads make the small dense solves of calibration 10-60x slower on few cores; it reads this
# once, when numpy is first imported, so it is set before anything imports numpy.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import logging
import sys

from rigctl import __version__
from rigctl.cli import (
    args,
    bench,
    board,
    calibrate,
    control,
    demo,
    depth,
    devices,
    plan,
    record,
    rectify,
    render,
    take,
    tally,
    tui,
)
from rigctl.errors import RigctlError

log = logging.getLogger(__name__)

VERBS = (plan, devices, record, take, tally, control, board, calibrate, rectify, depth, bench, demo, tui, render)


def build_parser() -> argparse.ArgumentParser:
    parser = args.OneLineParser(
        prog="rigctl",
        description="Run a planar camera array on set and turn its takes into colour + per-pixel depth.",
    )
    parser.add_argument("--version", action="version", version=f"rigctl {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logging")
    sub = parser.add_subparsers(dest="verb", metavar="COMMAND", parser_class=args.OneLineParser)
    for verb in VERBS:
        verb.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    ns = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if ns.debug else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if not getattr(ns, "func", None):
        parser.print_help()
        return 2
    try:
        return int(ns.func(ns))
    except RigctlError as exc:
        if ns.debug:
            raise
        sys.stderr.write(f"rigctl {ns.verb}: error: {exc}\n")
        return exc.exit_code
    except KeyboardInterrupt:
        sys.stderr.write(f"rigctl {ns.verb}: interrupted\n")
        return 130


if __name__ == "__main__":
    sys.exit(main())
