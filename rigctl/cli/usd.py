"""``rigctl usd``: the array's cameras as a USD stage (one UsdGeom.Camera per camera, metres, Y up)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.errors import ParameterError
from rigctl.planning.planner import FARTHEST_M, NEAREST_M
from rigctl.publish import utf8_path

log = logging.getLogger(__name__)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "usd",
        epilog=examples(
            ("the demo's calibrated cameras for Unreal, Blender, Houdini or NUKE",
             "rigctl usd rigctl-demo/calibration.yaml --out rig.usda"),
            ("a rectified take's cameras with the light-field window, clipped at the plan's range",
             "rigctl usd takes/ideal --out ideal.usda --rig sim-3x3 --window"),
        ),
        help="the cameras of a calibration or a rectified take as a USD stage (Unreal, Blender, Houdini, NUKE)",
        description="One UsdGeom.Camera per array camera: focal length and apertures from the rig's lens and "
        "the calibration, clipping range from the plan, the transform; metres, Y up.",
    )
    p.add_argument(
        "source", type=args.InputPath("SOURCE"), help="calibration.yaml, or a rectified take (its common camera)"
    )
    p.add_argument("--out", type=Path, required=True, help="new .usda (text), .usd or .usdc file")
    p.add_argument(
        "--rig",
        type=args.InputPath("--rig", text=True),
        help="rig file or shipped rig for the lens and the plan (default: the calibration's)",
    )
    p.add_argument("--near", type=args.distance, help="clipping near, metres (default: the plan's near)")
    p.add_argument("--far", type=args.far_distance, help="clipping far, metres (default: the plan's far)")
    p.add_argument("--window", action="store_true", help="add the light-field window (the cameras' plane) as a mesh")
    p.set_defaults(func=run)


# NEAREST_M, FARTHEST_M (the planner's): a clipping range USD's float holds, a renderer uses


def run(ns: argparse.Namespace) -> int:
    from rigctl.calibration_model import load_calibration
    from rigctl.interop.usd import rectified_calibration, write_stage
    from rigctl.planning.report import plan_rig
    from rigctl.rig import load_rig, rig_from_dict
    from rigctl.take.manifest import read_manifest

    utf8_path(ns.out)  # USD writes its layer's path as text
    if (ns.source / "take.yaml").is_file():
        calib = rectified_calibration(ns.source)
        rig = load_rig(ns.rig) if ns.rig else rig_from_dict(read_manifest(ns.source).rig, f"{ns.source}/take.yaml")
    elif ns.source.is_file():
        calib = load_calibration(ns.source)
        rig = load_rig(ns.rig or calib.rig)
    else:
        raise ParameterError(f"{ns.source}: neither a calibration file nor a take folder")
    plan = plan_rig(rig)
    near = ns.near if ns.near is not None else plan.near_m
    far = ns.far if ns.far is not None else plan.far_m
    # the background at infinity, or anything beyond this: as far as a float clipping range goes usefully
    far = min(far, FARTHEST_M)
    if not NEAREST_M <= near < far:
        raise ParameterError(
            f"--near {near:g} m: a clipping range runs from {NEAREST_M:g} m to {FARTHEST_M:g} m, near below far "
            f"(far {far:g} m)"
        )
    note = f"rigctl usd from {ns.source} (rig {rig.name}): metres, Y up; lens values in tenths of a metre"
    write_stage(calib, ns.out, rig.model.lens.focal_length_mm, (near, far), ns.window, note)
    print(f"wrote {len(calib.names)} cameras to {ns.out} (clipping {near:.3f}-{far:.3f} m)")
    return 0
