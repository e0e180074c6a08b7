"""``rigctl plan``: equations (1) and (2) for every camera pair of a rig."""

from __future__ import annotations

import argparse
import json

from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.planning.planner import check_derived_near, check_distances
from rigctl.planning.report import plan_rig
from rigctl.planning.text import format_plan
from rigctl.rig import load_rig


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan",
        epilog=examples(
            ("the nearest distance that keeps adjacent cameras within 4 % for a subject 1 m deep, on the paper's rig",
             "rigctl plan bmd-micro-studio-4k-3x3 --subject-depth 1"),
            ("check every camera pair for a subject from 2.5 m to a background at infinity",
             "rigctl plan sim-3x3 --near 2.5 --far inf"),
            ("the same plan as JSON, for a script", "rigctl plan sim-3x3 --subject-depth 1 --json"),
        ),
        help="near/far distances, parallax per camera pair, budget, disparity range",
        description=(
            "Apply equations (1) and (2) to every camera pair of RIG. With --subject-depth alone, solve the "
            "nearest distance that keeps the reference (adjacent horizontal) pair within the budget; with "
            "--near and --far, check every pair and name those over budget."
        ),
    )
    p.add_argument(
        "rig", nargs="?", type=args.InputPath("RIG", text=True), help="rig file or shipped rig name (default: sim-3x3)"
    )
    p.add_argument("--subject-depth", type=args.depth, metavar="M", help="depth of the subject in metres")
    p.add_argument("--near", type=args.distance, metavar="M", help="nearest point of the subject, metres")
    p.add_argument("--far", type=args.far_distance, metavar="M", help="farthest point, metres ('inf' allowed)")
    p.add_argument("--budget", type=args.fraction, metavar="F", help="parallax budget, fraction of the image")
    p.add_argument("--subject-width", type=args.extent("width"), metavar="M", help="check the subject fits every view")
    p.add_argument(
        "--subject-height", type=args.extent("height"), metavar="M", help="check the subject fits every view"
    )
    p.add_argument("--json", action="store_true", help="print the plan as JSON")
    p.set_defaults(func=run)


def _check_distances(ns: argparse.Namespace) -> None:
    """The distances a plan can mean (:func:`rigctl.planning.planner.check_distances`), named as options."""
    check_distances(ns.near, ns.far, ns.subject_depth, ("--near", "--far", "--subject-depth"))


def _check_near(ns: argparse.Namespace, near_m: float) -> None:
    """A near side the plan derived (solved from --subject-depth, or --far minus it) closer than 1 mm to the lens."""
    options = (("--far", ns.far, " m"), ("--subject-depth", ns.subject_depth, " m"), ("--budget", ns.budget, ""))
    given = " and ".join(f"{o} {v:g}{u}" for o, v, u in options if v is not None)
    check_derived_near(near_m, given or "the rig file plan section", "a deeper subject, or --near and --far")


def run(ns: argparse.Namespace) -> int:
    _check_distances(ns)
    rig = load_rig(ns.rig)
    plan = plan_rig(
        rig,
        subject_depth_m=ns.subject_depth,
        near_m=ns.near,
        far_m=ns.far,
        budget_fraction=ns.budget,
        subject_width_m=ns.subject_width,
        subject_height_m=ns.subject_height,
    )
    _check_near(ns, plan.near_m)
    if ns.json:
        print(json.dumps(plan.as_json(), indent=2, allow_nan=False))
    else:
        print(format_plan(plan, rig))
    return 0
