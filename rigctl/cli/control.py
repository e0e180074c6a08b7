"""``rigctl control``: set camera settings identically on every camera of the rig (or on one), and show for
each camera and setting whether the camera confirmed it."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict

from rigctl.camera_control import REFERENCE_SOURCES, check_settings, format_results, worst
from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.errors import ParameterError
from rigctl.registry import DeviceSet, open_cameras, open_control
from rigctl.rig import Rig, load_rig


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "control",
        epilog=examples(
            ("the same shutter and gain on every camera, each value confirmed by the camera's own report",
             "rigctl control sim-3x3 --exposure-us 10000 --gain 2"),
            ("white balance of one camera, as JSON",
             "rigctl control sim-3x3 --white-balance-k 5600 --camera r1c1 --json"),
        ),
        help="set exposure, gain, white balance, focus, aperture, reference on all cameras (or one)",
        description="Apply camera settings through the rig's camera-control path (camera_control: bridge). "
        "Each setting is reported per camera as confirmed (the camera reports the value), unconfirmed (the "
        "path cannot read values back), MISMATCH or FAILED; the exit status is 1 if any is MISMATCH or FAILED.",
    )
    p.add_argument(
        "rig", nargs="?", type=args.InputPath("RIG", text=True), help="rig file or shipped rig name (default: sim-3x3)"
    )
    p.add_argument("--exposure-us", type=float, metavar="N", help="exposure (shutter) time in microseconds")
    p.add_argument("--gain", type=float, metavar="N", help="sensor gain, protocol value: 1 = ISO 100, 2, 4, 8, 16")
    p.add_argument("--white-balance-k", type=float, metavar="N", help="white balance in kelvin")
    p.add_argument("--focus", type=float, metavar="X", help="focus, 0 (near end) .. 1 (far end)")
    p.add_argument("--aperture-f", type=float, metavar="F", help="aperture as an f-number, e.g. 2.8")
    p.add_argument("--reference", choices=REFERENCE_SOURCES, help="reference (genlock) source")
    p.add_argument(
        "--camera", action="append", type=args.camera, metavar="CAM", help="only this camera (repeatable; default: all)"
    )
    p.add_argument("--sim", action="append", default=[], metavar="KEY=VALUE", help="simulator setting (repeatable)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def _locks(rig: Rig, devices: DeviceSet, cameras: list[str]) -> dict[str, str]:
    out = {}
    for name in cameras:
        cam = devices.cameras.get(name)
        if cam is None:
            continue
        try:
            status = cam.status()
        except Exception:  # a device we could not ask: say so rather than guess
            out[name] = "not reported"
            continue
        if status.reference_locked is None:
            out[name] = "not reported by the capture path"
        else:
            out[name] = status.extra.get("reference", "locked" if status.reference_locked else "NOT LOCKED")
    return out


def run(ns: argparse.Namespace) -> int:
    rig = load_rig(ns.rig)
    wanted = {
        "exposure_us": ns.exposure_us,
        "gain": ns.gain,
        "white_balance_k": ns.white_balance_k,
        "focus": ns.focus,
        "aperture_f": ns.aperture_f,
        "reference": ns.reference,
    }
    values = check_settings({k: v for k, v in wanted.items() if v is not None})
    cameras = ns.camera or rig.camera_names
    for cam in cameras:
        if cam not in rig.camera_names:
            raise ParameterError(f"camera {cam!r} is not in rig {rig.name} (it has {', '.join(rig.camera_names)})")
    devices = open_cameras(rig, ns.sim, cameras)
    try:
        path = open_control(rig, devices)
        try:
            results = path.apply(values, cameras)
        finally:
            path.close()
        locks = _locks(rig, devices, cameras)
    finally:
        devices.close()
    if ns.json:
        print(json.dumps({"path": path.description, "results": [asdict(r) for r in results], "reference": locks}))
    else:
        print(f"camera control through {path.description}")
        print(format_results(results, locks))
    return worst(results)
