"""``rigctl depth``: disparity and depth for every requested camera of a rectified take or grid folder."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from rigctl.cli import args
from rigctl.cli.args import add_layout, add_pipeline_options, depth_options, distance, far_distance
from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet
from rigctl.cli.take import damaged_exit
from rigctl.depth.presets import PRESETS
from rigctl.depth.run import run_depth
from rigctl.errors import ParameterError
from rigctl.publish import output_folder, publish_json
from rigctl.take.framesets import parse_frames


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "depth",
        epilog=examples(
            ("every camera of the demo's rectified take, frame set 0, within the planned range",
             "rigctl depth rigctl-demo/takes/presenter-rectified --out depth --frames 0 --near 1.95 --far 2.95"),
            ("one camera of an ideal simulated take (already rectified), fast preset, scored against the truth",
             "rigctl depth takes/ideal --out ideal-depth --cameras r1c1 --preset fast"),
            ("an EXR sequence per camera for NUKE", "rigctl depth takes/ideal --out ideal-nuke --layout sequence"),
            ("the disparity as PFM and a colour preview beside the EXR",
             "rigctl depth takes/ideal --out ideal-all --cameras r1c1 --formats exr,pfm,png"),
        ),
        help="per-camera disparity and depth of a rectified take or grid folder (EXR; PFM, PNG when asked)",
        description="Multi-baseline depth: every other camera of the grid with its own baseline, only the keyed "
        "subject, only the planned disparity range (from --near/--far). Writes <frame>/<camera>.exr (scene-linear "
        "RGB and A, disparityL/R/V as NUKE names them: onto the camera right/left/below, depth.Z = 1/Z), "
        "with --formats also .pfm (disparity, +inf where none) and .png (red near, "
        "blue far), and report.json (--layout sequence: <camera>/<camera>.<frame>.exr). Presets: "
        + "; ".join(f"{p.name}: {p.description}" for p in PRESETS.values()),
    )
    p.add_argument(
        "input",
        type=args.InputPath("INPUT"),
        metavar="INPUT",
        help="rectified take, ideal simulated take, or grid folder",
    )
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.add_argument("--preset", choices=list(PRESETS), default="best")
    p.add_argument("--near", type=distance, metavar="M", help="nearest subject distance (planner range)")
    p.add_argument("--far", type=far_distance, metavar="M", help="farthest subject distance (inf allowed)")
    p.add_argument("--cameras", nargs="+", type=args.camera, metavar="CAM", help="cameras to compute (default: all)")
    p.add_argument("--frames", metavar="A-B", help="frame sets (default: all complete ones)")
    p.add_argument("--no-key", action="store_true", help="search every pixel (no green-screen key)")
    p.add_argument(
        "--skip-damaged",
        action="store_true",
        help="leave out frame sets with a damaged or missing frame, list them in report.json and exit 5",
    )
    add_pipeline_options(p)
    add_layout(p)
    p.add_argument("--json", action="store_true")
    p.add_argument("--check", action="store_true", help="add leave-one-out PSNR/SSIM (rigctl render) to report.json")
    add_quiet(p)
    p.set_defaults(func=run)


def refuse_out_over_input(source: Path, out: Path) -> None:
    """``--out`` may not be the input folder or lie in its ``truth/``: a grid folder's outputs are named as its
    pictures (``r1c1.png``) and a take's as its truth (``truth/disparity/<frame>/<camera>.pfm``), so depth
    would write over what it reads."""
    src, dst = Path(os.path.realpath(source)), Path(os.path.realpath(out))  # resolve() raises on a symlink loop
    if dst == src or dst.is_relative_to(src / "truth"):
        raise ParameterError(f"--out {out}: is the input {source} or its truth: depth would write over its files")


def run(ns: argparse.Namespace) -> int:
    frames = parse_frames(ns.frames) if ns.frames else None
    opt = depth_options(ns)
    if ns.check and ns.cameras is not None and len(set(ns.cameras)) < 2:
        raise ParameterError(
            "--check renders each computed camera from the others: give at least two --cameras, or none for all"
        )
    refuse_out_over_input(ns.input, ns.out)
    with output_folder(ns.out, "depth"):  # usable, locked for this run, an interrupted run's leftovers removed
        with Progress(f"depth {ns.input.name}", "cameras", ns.quiet) as bar:
            report = run_depth(
                ns.input,
                ns.out,
                opt,
                frames,
                ns.formats,
                progress=bar.update,
                skip_damaged=ns.skip_damaged,
                layout=ns.layout,
                colour=ns.colour,
            )
        data = report.to_json()
        if ns.check:
            from rigctl.cli.render import leave_one_out_report

            data["leave_one_out"] = leave_one_out_report(ns.input, ns.out, frames, ns.cameras)
            publish_json(ns.out / "report.json", data, default=float)
    status = damaged_exit(report.damaged_skipped, ns.out / "report.json")
    if ns.json:
        print(json.dumps(data, default=float))
        return status
    rng = report.range
    print(
        f"take range {rng.disparity_range_px[0]:.1f}..{rng.disparity_range_px[1]:.1f} px ({rng.source}); "
        f"bound hit on {report.bound_hit_pixels} px in all"
    )
    for n, fr in report.frames.items():
        lo, hi = fr.disparity_range_px
        print(
            f"frame {n}: {len(fr.cameras)} cameras, disparity {lo:.1f}..{hi:.1f} px, "
            f"keyed background {fr.keyed_background_share:.0%}, bound hit on {fr.bound_hit_pixels} px, "
            f"{fr.timings_s.depth:.1f} s"
        )
        for cam in fr.cameras:
            truth = fr.truth(cam)
            if truth is not None:
                print(
                    f"  {cam}: bad 1.0 {truth.bad_1_0:.2f} %, bad 2.0 {truth.bad_2_0:.2f} %, false foreground "
                    f"{truth.false_fg_pct:.3f} %, missed {truth.missed_fg_pct:.3f} % against the truth"
                )
    for cam, v in report.video.items():
        if v.static_change_mean_px is not None:
            print(
                f"{cam} over time: change where the truth is still {v.static_change_mean_px:.3f} px mean, "
                f"{v.static_change_over_0_5_pct:.2f} % above 0.5 px"
            )
    print(f"wrote {ns.out} in {report.seconds:.1f} s")
    return status
