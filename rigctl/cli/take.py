"""``rigctl take info | check | export``."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from rigctl.cli import args
from rigctl.cli.args import add_layout
from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet
from rigctl.cli.record import format_summary
from rigctl.errors import EXIT_DAMAGED
from rigctl.publish import output_folder, refuse_inside, utf8_path
from rigctl.take.check import check_take
from rigctl.take.export import export_take
from rigctl.take.manifest import DamagedFrame
from rigctl.take.reader import TakeReader


def register(sub: argparse._SubParsersAction) -> None:
    summary = ("frames, drops and skew of a take", "rigctl take info takes/T001")
    whole = ("every frame's checksum read back", "rigctl take check takes/T001")
    png = ("frame sets 0 to 2 as 8-bit pictures", "rigctl take export takes/T001 --out T001-png --frames 0-2")
    p = sub.add_parser("take", help="inspect, check and export takes", epilog=examples(summary, whole, png))
    verbs = p.add_subparsers(dest="take_verb", metavar="info|check|export", required=True)
    as_json = ("the same as JSON", "rigctl take info rigctl-demo/takes/presenter --json")
    info = verbs.add_parser("info", help="frames, drops, complete frame sets, skew", epilog=examples(summary, as_json))
    info.add_argument("take", type=args.InputPath("TAKE"))
    info.add_argument("--json", action="store_true")
    info.set_defaults(func=run_info)
    quick = ("the manifest and indexes only", "rigctl take check rigctl-demo/takes/presenter --quick")
    what = "is everything the take claims readable? (exit 0 when it is)"
    check = verbs.add_parser("check", help=what, epilog=examples(whole, quick))
    check.add_argument("take", type=args.InputPath("TAKE"))
    check.add_argument("--quick", action="store_true", help="skip reading every frame's checksum")
    check.set_defaults(func=run_check)
    export = verbs.add_parser(
        "export",
        help="frame sets as DIR/<frame>/<camera>.png or .exr",
        epilog=examples(
            png,
            ("scene-linear ACEScg EXR with the key as alpha, an image sequence per camera for NUKE",
             "rigctl take export takes/T001 --out T001-exr --format exr --colour acescg --layout sequence"),
        ),
    )
    export.add_argument("take", type=args.InputPath("TAKE"))
    export.add_argument("--out", type=Path, required=True, metavar="DIR")
    export.add_argument("--frames", metavar="A-B", help="N or A-B, frame-set numbers from 0 (default: all)")
    export.add_argument("--format", default="png", choices=("png", "exr"))
    export.add_argument(
        "--skip-damaged",
        action="store_true",
        help="leave out frames that fail their checksum or are missing, list them in DIR/export.json and exit 5",
    )
    add_layout(export)
    add_quiet(export)
    export.set_defaults(func=run_export)


def run_info(ns: argparse.Namespace) -> int:
    reader = TakeReader(ns.take, skip_damaged=True)  # a summary: damage is counted, `take check` locates it
    summary = reader.summary()
    if reader.damaged:
        print(
            f"warning: {len(reader.damaged)} damaged item(s); rigctl take check {ns.take} locates them", file=sys.stderr
        )
    print(json.dumps(summary, indent=2) if ns.json else format_summary(summary))
    return 0


def run_check(ns: argparse.Namespace) -> int:
    report = check_take(ns.take, verify_data=not ns.quick)
    for w in report.warnings:
        print(f"warning: {w}", file=sys.stderr)
    for e in report.errors:
        print(f"error: {e}", file=sys.stderr)
    if report.ok:
        print(f"{ns.take}: ok ({report.frames_checked} frames checked)")
        return 0
    print(f"{ns.take}: {len(report.errors)} problem(s)", file=sys.stderr)
    return 1


def run_export(ns: argparse.Namespace) -> int:
    utf8_path(ns.out)
    refuse_inside(ns.out, ns.take)
    reader = TakeReader(ns.take, skip_damaged=ns.skip_damaged)
    with (
        output_folder(ns.out, "take export"),  # locked for this run; an interrupted run's leftovers removed
        Progress(f"exporting {reader.manifest.take}", "frame sets", ns.quiet) as bar,
    ):
        result = export_take(
            reader, ns.out, ns.frames, ns.format, progress=bar.steps, layout=ns.layout, colour=ns.colour
        )
    print(
        f"{result['images']} images from {result['sets']} frame sets written to {ns.out}"
        + (f" ({result['missing']} members not captured)" if result["missing"] else "")
    )
    return damaged_exit(reader.damaged, ns.out / "export.json")


def damaged_exit(damaged: Sequence[DamagedFrame], listed_in: Path) -> int:
    """0, or the data-damaged exit status after saying on stderr what was left out and where it is listed."""
    if not damaged:
        return 0
    first = damaged[0]
    print(
        f"warning: damaged data left out ({len(damaged)} item(s)), listed in {listed_in} "
        f"(first: {first.file}: byte {first.byte}: {first.problem})",
        file=sys.stderr,
    )
    return EXIT_DAMAGED
