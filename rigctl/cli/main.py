"""Entry point of the ``rigctl`` console script.

Every error a user can cause is a :class:`~rigctl.errors.RigctlError`: it becomes one line on stderr and
a non-zero exit code (one per class of error, :mod:`rigctl.errors`). ``--debug``, anywhere on the command
line, shows the traceback instead. Output into a pipe that closes early (``rigctl plan --json | head -1``)
ends quietly.
"""

from __future__ import annotations

import os

# OpenBLAS's threads make the small dense solves of calibration 10-60x slower on few cores; it reads this
# once, when numpy is first imported, so it is set before anything imports numpy.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import importlib
import logging
import sys
from pathlib import Path

from rigctl import __version__
from rigctl.allocator import limit_arenas
from rigctl.cli import args, stdout
from rigctl.cli.helptext import examples
from rigctl.errors import EXIT_INTERRUPTED, EXIT_USAGE, RigctlError
from rigctl.publish import output_error

log = logging.getLogger(__name__)

# one module per verb under rigctl.cli, each with register(sub); a command line that names its verb imports
# only that module (and what it needs), not every verb's libraries: start-up is part of a take's start
VERBS = (
    "plan", "devices", "record", "take", "tally", "control", "board", "calibrate", "rectify", "depth", "process",
    "render", "bench", "demo", "tui", "miv", "usd", "view", "completion",
)  # fmt: skip
# the verbs that estimate depth in this process: one allocator arena (rigctl.allocator)
DEPTH_VERBS = ("depth", "process", "bench", "demo")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole command line, or with ``only`` just that verb's part (usage and errors still name
    ``rigctl VERB``)."""
    parser = args.OneLineParser(
        prog="rigctl",
        description="Run a planar camera array on set and turn its takes into colour + per-pixel depth.",
        epilog=examples(
            ("the whole chain on the simulated rig, ending with rigctl-demo/report.md (1-2 minutes)",
             "rigctl demo --out rigctl-demo"),
            ("the nearest distance for a subject 1 m deep on the paper's rig",
             "rigctl plan bmd-micro-studio-4k-3x3 --subject-depth 1"),
            ("ten frame sets from the simulated rig into ./takes/T001",
             "rigctl record sim-3x3 --take T001 --frames 10 --sim deterministic=true"),
            ("what a command takes, with its own examples", "rigctl depth --help"),
            ("completion of commands, options, rigs and cameras in bash (rigctl completion --help: installing it)",
             "source <(rigctl completion bash)"),
        ),
    )
    parser.add_argument("--version", action="version", version=f"rigctl {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logging")
    sub = parser.add_subparsers(dest="verb", metavar="COMMAND", parser_class=args.OneLineParser)
    for verb in VERBS if only is None else (only,):
        importlib.import_module(f"rigctl.cli.{verb}").register(sub)
    return parser


def _verb(argv: list[str]) -> str | None:
    """The verb a command line names (the first word that is not an option), when it is one of ours."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return word if word in VERBS else None


def _take_debug(argv: list[str]) -> tuple[list[str], bool]:
    """``argv`` without ``--debug`` (accepted before or after the verb, up to a ``--``), and whether it was there."""
    end = argv.index("--") if "--" in argv else len(argv)
    head = [a for a in argv[:end] if a != "--debug"]
    return head + argv[end:], len(head) != end


def _run(argv: list[str], debug: bool) -> int:
    parser = build_parser(_verb(argv))
    ns = parser.parse_args(argv)
    ns.debug = debug
    logging.basicConfig(
        level=logging.DEBUG if ns.debug else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    if not getattr(ns, "func", None):
        parser.print_help()
        return EXIT_USAGE
    if ns.verb in DEPTH_VERBS:
        limit_arenas()  # before any of the verb's threads allocate (recording keeps glibc's default)
    return int(ns.func(ns))


def main(argv: list[str] | None = None) -> int:
    argv, debug = _take_debug(list(sys.argv[1:] if argv is None else argv))
    verb = _verb(argv)
    prog = f"rigctl {verb}" if verb else "rigctl"
    # a stdout that is full, failing or closed is one line wherever it is written, help and parser included
    saved, sys.stdout = sys.stdout, stdout.guard(sys.stdout)
    try:
        code = _run(argv, debug)
        sys.stdout.flush()  # a closed pipe or a full stdout shows here, inside the handler, not at interpreter exit
        return code
    except BrokenPipeError:
        stdout.to_devnull(1)  # the reader went away: what is left goes nowhere and nothing more is reported
        return 0
    except RigctlError as exc:
        if debug:
            raise
        sys.stderr.write(f"{prog}: error: {exc}\n")
        return exc.exit_code
    except OSError as exc:  # the output side's last line of defence: a file that could not be written or read
        if debug or exc.filename is None:
            raise
        error = output_error(Path(os.fsdecode(exc.filename)), exc)
        sys.stderr.write(f"{prog}: error: {error}\n")
        return error.exit_code
    except KeyboardInterrupt:
        sys.stderr.write(f"{prog}: interrupted\n")
        return EXIT_INTERRUPTED
    finally:
        sys.stdout = saved


if __name__ == "__main__":
    sys.exit(main())
