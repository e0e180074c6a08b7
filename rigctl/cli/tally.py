"""``rigctl tally``: send the complete tally state once and exit."""

from __future__ import annotations

import argparse

from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.registry import open_tally
from rigctl.rig import load_rig
from rigctl.tally import tally_state


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tally",
        help="send the complete tally state (program / preview) once",
        epilog=examples(
            (
                "the centre camera on program, its left and right neighbours on preview",
                "rigctl tally sim-3x3 --program r1c1 --preview r1c0 r1c2",
            ),
            ("every lamp off", "rigctl tally sim-3x3"),
        ),
    )
    p.add_argument(
        "rig", nargs="?", type=args.InputPath("RIG", text=True), help="rig file or shipped rig name (default: sim-3x3)"
    )
    p.add_argument(
        "--program", nargs="*", default=[], type=args.camera, metavar="CAM", help="cameras on program (live)"
    )
    p.add_argument("--preview", nargs="*", default=[], type=args.camera, metavar="CAM", help="cameras on preview")
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    rig = load_rig(ns.rig)
    state = tally_state(rig, ns.program, ns.preview)  # refused before the line is opened
    out = open_tally(rig)
    try:
        out.send(state)
        out.settle()  # a receiver that drops the connection at once did not show it
    finally:
        out.close()
    print(
        f"tally sent to {rig.model.tally.port if rig.model.tally else '?'}: program {', '.join(ns.program) or '-'}; "
        f"preview {', '.join(ns.preview) or '-'}"
    )
    return 0
