"""``rigctl tui``: the shoot-time terminal UI."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.errors import ParameterError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tui",
        epilog=examples(
            ("the shoot on the simulated rig: takes S01-01-T01, T02, ... in ./takes", "rigctl tui sim-3x3 --out takes"),
            ("scene 12, shot 3, the simulated cameras filming the ChArUco board",
             "rigctl tui sim-3x3 --scene S12 --shot 03 --sim scene=charuco"),
        ),
        help="the shoot: camera tiles, record with r, tally, camera settings, planner",
        description="A terminal UI for the shoot. Cameras stream as soon as it opens; r records a take of every "
        "camera into OUT (named SCENE-SHOT-Tnn, numbered on), q quits (asking first while recording), ? lists keys.",
    )
    p.add_argument(
        "rig", nargs="?", type=args.InputPath("RIG", text=True), help="rig file or shipped rig name (default: sim-3x3)"
    )
    p.add_argument("--out", type=Path, default=Path("takes"), metavar="DIR", help="where takes go (default: ./takes)")
    p.add_argument("--scene", default="S01", help="scene name (default S01)")
    p.add_argument("--shot", default="01", help="shot name (default 01)")
    p.add_argument("--sim", action="append", default=[], metavar="KEY=VALUE", help="simulator setting (repeatable)")
    p.add_argument("--no-thumbnails", action="store_true", help="no pictures in the tiles")
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    from rigctl.rig import load_rig
    from rigctl.take.names import check_take_name
    from rigctl.tui.app import ShootApp
    from rigctl.tui.session import Session

    if not (sys.stdin.isatty() and sys.stdout.isatty()):  # it would draw into a file and never stop
        raise ParameterError("needs a terminal on its input and output (not a pipe, a file or /dev/null)")
    rig = load_rig(ns.rig)
    check_take_name(f"{ns.scene}-{ns.shot}-T01")

    def factory() -> Session:
        return Session(rig, ns.out, ns.sim, ns.scene, ns.shot)

    ShootApp(factory, thumbnails=not ns.no_thumbnails, rig=rig).run()
    return 0
