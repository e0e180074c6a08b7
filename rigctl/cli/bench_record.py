"""``rigctl bench record``: the recorder's throughput on 10-bit frames (Y210, v210) beside 8-bit ones (UYVY)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
from pathlib import Path

from rigctl.cli.helptext import examples
from rigctl.cli.render import size
from rigctl.errors import ParameterError
from rigctl.publish import utf8_path


def register_bench(what: argparse._SubParsersAction) -> None:
    b = what.add_parser(
        "record",
        help="the recorder's throughput on nine 10-bit streams (Y210, v210; stored at 20 bits a pixel) beside "
        "nine 8-bit ones (UYVY), taking turns in one run",
        epilog=examples(
            ("nine 1080p streams of each format, three takes each (a minute or two)", "rigctl bench record"),
            (
                "a quick look: small frames, one short take each, as JSON",
                "rigctl bench record --size 192x108 --frames 4 --rounds 1 --json",
            ),
        ),
    )
    b.add_argument("--size", type=size, default=(1920, 1080), metavar="WxH", help="default 1920x1080")
    b.add_argument("--frames", type=int, default=25, metavar="N", help="frame sets a take (default 25)")
    b.add_argument("--rounds", type=int, default=3, metavar="R", help="takes per format, taking turns (median kept)")
    b.add_argument("--dir", type=Path, metavar="DIR", help="destination (default: a temporary folder)")
    b.add_argument("--json", action="store_true")
    b.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    from rigctl.capture.bench import bench_record, format_bench

    if ns.frames < 1 or ns.rounds < 1:
        raise ParameterError(f"--frames and --rounds must be at least 1, got {ns.frames} and {ns.rounds}")
    w, h = ns.size
    if w % 2:
        raise ParameterError(f"--size {w}x{h}: 4:2:2 needs an even width")
    if ns.dir is not None:
        utf8_path(ns.dir, "--dir")
        ns.dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="rigctl-bench-record-", dir=ns.dir) as tmp:
        results = bench_record(Path(tmp), w, h, ns.frames, ns.rounds)
    if ns.json:
        print(json.dumps([dataclasses.asdict(r) for r in results], indent=2))
    else:
        print(format_bench(results, w, h, ns.frames, ns.rounds))
    return 0
