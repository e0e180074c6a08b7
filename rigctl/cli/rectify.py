"""``rigctl rectify``: common-plane grid rectification of a take into a new take."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet
from rigctl.cli.take import damaged_exit
from rigctl.rectification.rectify import rectify_take


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "rectify",
        epilog=examples(
            ("the demo's presenter take with the demo's calibration",
             "rigctl rectify rigctl-demo/takes/presenter --calibration rigctl-demo/calibration.yaml "
             "--out presenter-rectified"),
            ("a simulated take with the simulator's true calibration",
             "rigctl rectify takes/T001 --calibration takes/T001/truth/calibration.yaml --out takes/T001-rectified"),
        ),
        help="rectify a take onto the array's common plane (rows along rows, columns along columns)",
        description="Warp every frame of TAKE into one shared orientation and camera matrix fitted to the "
        "calibrated camera centres, so that a point lies on the same row in horizontal neighbours and the same "
        "column in vertical neighbours. The result is a take (8-bit BGR) with its rectification recorded. Remap "
        "tables are cached by a hash of the calibration ($XDG_CACHE_HOME/rigctl/remap).",
    )
    p.add_argument("take", type=args.InputPath("TAKE"), metavar="TAKE")
    p.add_argument(
        "--calibration", type=args.InputPath("--calibration"), required=True, metavar="FILE", help="calibration.yaml"
    )
    p.add_argument("--out", type=Path, required=True, metavar="RECTIFIED_TAKE", help="the new take's folder")
    p.add_argument(
        "--skip-damaged",
        action="store_true",
        help="leave out source frames that fail their checksum or are missing, list them in the new take.yaml "
        "(damaged_skipped) and exit 5",
    )
    p.add_argument("--json", action="store_true")
    add_quiet(p)
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    # built under a partial name and renamed once whole: no half-rectified take is ever left behind
    with Progress(f"rectifying {ns.take.name}", "frames", ns.quiet) as bar:
        summary = rectify_take(ns.take, ns.calibration, ns.out, bar.steps, skip_damaged=ns.skip_damaged)
    if ns.json:
        print(json.dumps(summary.to_json()))
    else:
        w, h = summary.image_size
        print(
            f"rectified {summary.frames} frames into {summary.take}: {w}x{h}, f = {summary.focal_px:.1f} px; "
            f"tables {'from cache' if summary.tables_cached else 'built'} in {summary.tables_s:.2f} s, "
            f"remap {summary.remap_s:.2f} s of {summary.total_s:.2f} s"
        )
    return damaged_exit(summary.damaged_skipped, ns.out / "take.yaml")
