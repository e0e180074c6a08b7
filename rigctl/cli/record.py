"""``rigctl record``: a take from every camera of a rig."""

from __future__ import annotations

import argparse
import json
import signal
from pathlib import Path
from types import FrameType

from rigctl.cli.progress import Progress
from rigctl.errors import ParameterError
from rigctl.preflight import PreflightError, check_destinations
from rigctl.recorder import Recorder, TakePlan
from rigctl.registry import open_cameras
from rigctl.rig import load_rig
from rigctl.take.names import check_take_name
from rigctl.take.reader import TakeReader


def register(sub: argparse._SubParsersAction) -> None:
    from rigctl.registry import sim_settings_help

    p = sub.add_parser(
        "record",
        help="record a take from every camera",
        description="Record a take from every camera of RIG into OUT/NAME.",
        epilog="simulated cameras take these --sim settings (KEY=VALUE; per camera KEY.rXcY=VALUE):\n"
        + sim_settings_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("rig", nargs="?", help="rig file or shipped rig name (default: sim-3x3)")
    p.add_argument("--take", required=True, metavar="NAME", help="take name (a folder name: letters, digits, . _ -)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--frames", type=int, metavar="N", help="frame sets to record")
    length.add_argument("--seconds", type=float, metavar="S", help="seconds to record")
    p.add_argument("--scene", help="simulated scene (presenter, charuco); same as --sim scene=SCENE")
    p.add_argument("--sim", action="append", default=[], metavar="KEY=VALUE", help="simulator setting (repeatable)")
    p.add_argument("--out", type=Path, default=Path("takes"), metavar="DIR", help="destination (default: ./takes)")
    p.add_argument(
        "--dest",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="further destinations: cameras are spread over --out and these",
    )
    p.add_argument("--force", action="store_true", help="record even if preflight finds the disks too slow")
    p.add_argument("--no-checksum", action="store_true", help="skip per-frame CRC-32 (saves CPU at high rates)")
    p.add_argument(
        "--buffers",
        type=int,
        metavar="N",
        help="frame buffers per camera (default: a second of frames within a 3 GB budget)",
    )
    p.add_argument("--json", action="store_true", help="print the take's summary as JSON")
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    rig = load_rig(ns.rig)
    name = check_take_name(ns.take)
    if ns.frames is not None and ns.frames <= 0:
        raise ParameterError(f"--frames must be a positive number of frame sets, got {ns.frames}")
    if ns.seconds is not None and not ns.seconds > 0:
        raise ParameterError(f"--seconds must be positive, got {ns.seconds}")
    frames = ns.frames if ns.frames is not None else (round(ns.seconds * rig.fps) if ns.seconds else None)
    sim = list(ns.sim) + ([f"scene={ns.scene}"] if ns.scene else [])
    devices = open_cameras(rig, sim)
    destinations = [ns.out, *ns.dest]
    plan = TakePlan.spread(name, destinations, sorted(devices.cameras, key=rig.camera_names.index))
    per_camera_bps = rig.width_px * rig.height_px * 2 * rig.fps
    by_dest: dict[Path, list[str]] = {}
    for cam, folder in plan.camera_folders.items():
        by_dest.setdefault(folder.parent.parent, []).append(cam)
    report = check_destinations(by_dest, per_camera_bps, frames / rig.fps if frames else None)
    if not report.ok and not ns.force:
        devices.close()
        raise PreflightError(
            report.problems[0] + (f" (and {len(report.problems) - 1} more)" if len(report.problems) > 1 else "")
        )
    if ns.buffers is not None and ns.buffers < 2:
        raise ParameterError(f"--buffers must be at least 2, got {ns.buffers}")
    recorder = Recorder(rig, devices, plan, checksum=not ns.no_checksum, buffers_per_camera=ns.buffers)
    bar = Progress(f"recording {name}")
    previous = signal.getsignal(signal.SIGINT)

    def on_interrupt(signum: int, frame: FrameType | None) -> None:
        recorder.stop()

    try:
        recorder.arm()
        signal.signal(signal.SIGINT, on_interrupt)
        recorder.start(frames)
        recorder.wait(progress=bar)
    finally:
        signal.signal(signal.SIGINT, previous)
        manifest = recorder.finish()
        bar.close()
    reader = TakeReader(plan.folder, skip_damaged=True)  # the summary of what was written
    summary = reader.summary()
    summary["path"] = str(plan.folder)
    if ns.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
    if recorder.error is not None:
        raise recorder.error
    return 0 if manifest else 1


def format_summary(s: dict) -> str:
    cams = s["cameras"]
    lines = [
        f"take {s['take']} ({s['status']}): {s['frame_sets']} frame sets, {s['complete_sets']} complete, "
        f"{len(cams)} cameras, {s['format']}",
    ]
    skew = s["skew"]
    lines.append(f"skew within frame sets: p50 {skew['p50_us']} us, p99 {skew['p99_us']} us, max {skew['max_us']} us")
    for name, c in cams.items():
        lost = {
            k: c[k] for k in ("source_drops", "error_frames", "writer_drops", "not_written", "torn_excluded") if c[k]
        }
        lines.append(f"  {name}: {c['frames']} frames" + (f", {lost}" if lost else ""))
    if s.get("end"):
        end = s["end"]
        lines.append(f"ended: {end.get('reason', '')}" + (f": {end['message']}" if end.get("message") else ""))
    for note in s.get("notes", []):
        lines.append(f"note: {note}")
    if "path" in s:
        lines.append(f"written to {s['path']}")
    return "\n".join(lines)
