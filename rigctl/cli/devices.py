"""``rigctl devices``: what is attached, and how it maps onto the rig."""

from __future__ import annotations

import argparse
import json

from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.discovery import describe_attached
from rigctl.rig import load_rig


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "devices",
        help="attached capture devices and their mapping onto the rig",
        epilog=examples(
            ("the V4L2 capture devices on this machine and which of the paper's rig's cameras they are "
             "(exit 1 while any is missing)", "rigctl devices bmd-micro-studio-4k-3x3"),
            ("the simulated rig's cameras, tally and bridge, as JSON", "rigctl devices sim-3x3 --json"),
        ),
    )
    p.add_argument(
        "rig", nargs="?", type=args.InputPath("RIG", text=True), help="rig file or shipped rig name (default: sim-3x3)"
    )
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    rig = load_rig(ns.rig)
    attached = describe_attached(rig)
    if ns.json:
        print(json.dumps(attached, indent=2))
        return 0 if not attached["missing"] else 1
    v4l2 = attached["v4l2"]
    print(f"V4L2 capture devices: {len(v4l2) if v4l2 else 'none'}")
    for d in v4l2:
        if d.get("error"):
            print(f"  {d['path']}: {d['error']}")
            continue
        fmts = ", ".join(d["formats"][:6]) + (" ..." if len(d["formats"]) > 6 else "")
        print(f"  {d['path']}: {d['card']} ({d['driver']}, {d['bus']}) signal {d['signal']}; formats {fmts}")
    serial = attached["serial"]
    print(f"serial ports: {len(serial) if serial else 'none'}")
    for port in serial:
        usb = f" USB {port['usb']} serial {port['serial'] or '-'} at {port['location'] or '?'}" if port["usb"] else ""
        print(f"  {port['device']}: {port['description']}{usb}")
    usb_devices = attached["usb"]
    print(f"USB devices: {len(usb_devices) if usb_devices else 'none'}")
    for dev in usb_devices:
        print(f"  {dev.get('describe') or dev.get('error')}")
    print(f"rig {rig.name}:")
    for cam in attached["cameras"]:
        state = cam["state"]
        where = f" -> {cam['resolved']}" if cam.get("resolved") and cam["resolved"] != cam["device"] else ""
        print(f"  {cam['name']}: {cam['device']}{where}  {state}")
    for line in attached["lines"]:
        print(f"  {line['role']}: {line['address']}  {line['state']}")
    for ident in attached["usb_identities"]:
        print(f"  USB identity of {ident['role']}: {ident.get('device') or ident.get('error')}")
    if attached["missing"]:
        print(f"missing: {', '.join(attached['missing'])}")
        return 1
    return 0
