"""``rigctl bench depth``: error against run time, presets and OpenCV baselines measured in the same run."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rigctl.cli.progress import Progress


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="benchmarks that report error against run time")
    what = p.add_subparsers(dest="what", metavar="WHAT")
    d = what.add_parser(
        "depth",
        help="every depth preset and the OpenCV baselines on the simulated presenter, Middlebury Motorcycle and "
        "the stratified light-field scenes",
    )
    d.add_argument("--repeats", type=int, default=1, help="runs per method (the median time is kept)")
    d.add_argument("--plot", type=Path, default=Path("bench-depth.png"), metavar="PNG")
    d.add_argument("--json", action="store_true")
    d.add_argument("--quick", action="store_true", help="realistic presenter and Motorcycle only")
    d.set_defaults(func=run_depth_bench)
    p.set_defaults(func=lambda ns: (p.print_help(), 2)[1])


def run_depth_bench(ns: argparse.Namespace) -> int:
    from rigctl.benchdata import presenter
    from rigctl.depth.bench import format_table, motorcycle, plot, run_bench, stratified
    from rigctl.errors import ParameterError

    if ns.repeats < 1:
        raise ParameterError(f"--repeats must be at least 1, got {ns.repeats}")
    bar = Progress("bench depth")
    try:
        datasets = ([] if ns.quick else [presenter(True)]) + [presenter(False), motorcycle(), *stratified()]
        result = run_bench(datasets, repeats=ns.repeats, progress=bar)
    finally:
        bar.close()
    plot(result, ns.plot)
    if ns.json:
        print(json.dumps(result, default=float))
    else:
        print(format_table(result))
        print(f"plot: {ns.plot}")
    return 0
