"""``rigctl demo``: the whole chain on the simulated rig, ending with a report in the folder it names."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        epilog=examples(
            ("the whole chain on the simulated rig, ending with rigctl-demo/report.md",
             "rigctl demo --out rigctl-demo"),
            ("again, replacing a finished demo", "rigctl demo --out rigctl-demo --fresh"),
        ),
        help="plan, record, calibrate, rectify, depth and benchmark on the simulated rig, with a report",
        description="Runs every stage on the simulated sim-3x3 rig: plan; record a ChArUco take; calibrate; "
        "record a presenter take; rectify; depth for all cameras; error against run time for the presets and "
        "OpenCV. Writes OUT/report.md with its figures. Takes a few minutes on two cores.",
    )
    p.add_argument("--out", type=Path, default=Path("rigctl-demo"), metavar="DIR", help="(default: ./rigctl-demo)")
    p.add_argument(
        "--fresh",
        action="store_true",
        help="replace a finished demo in DIR (an unfinished one is always replaced; a folder with no demo, never)",
    )
    add_quiet(p)
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    from rigctl.demo import run_demo

    def say(text: str) -> None:
        print(text, flush=True)

    report = run_demo(ns.out, say, lambda label, unit: Progress(label, unit, ns.quiet), fresh=ns.fresh)
    print(f"\nreport: {report}", file=sys.stdout)
    return 0
