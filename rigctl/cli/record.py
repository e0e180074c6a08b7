"""``rigctl record``: a take from every camera of a rig."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from rigctl.capture.preflight import PreflightReport, rate_text
from rigctl.capture.recording import record_take
from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet
from rigctl.errors import ParameterError
from rigctl.publish import utf8_path
from rigctl.rig import load_rig
from rigctl.take.names import check_take_name
from rigctl.take.reader import TakeReader


def register(sub: argparse._SubParsersAction) -> None:
    from rigctl.registry import sim_settings_help

    p = sub.add_parser(
        "record",
        help="record a take from every camera",
        description="Record a take from every camera of RIG into OUT/NAME.",
        epilog=examples(
            ("ten frame sets of the simulated presenter into ./takes/T001, the same bytes on any machine",
             "rigctl record sim-3x3 --take T001 --frames 10 --sim deterministic=true"),
            ("a ChArUco board take for rigctl calibrate",
             "rigctl record sim-3x3 --take board --frames 24 --scene charuco --sim board_poses=24 "
             "--sim deterministic=true"),
            ("an ideal take (a perfect lattice: already rectified, with exact truth) for depth and render",
             "rigctl record sim-3x3 --take ideal --frames 3 --sim ideal=true --sim deterministic=true"),
            ("five seconds in real time, cameras spread over two disks",
             "rigctl record sim-3x3 --take S01-01-T01 --seconds 5 --out takes --dest takes-b"),
            before="simulated cameras take these --sim settings (KEY=VALUE; per camera KEY.rXcY=VALUE):\n"
            + sim_settings_help(),
        ),
    )
    p.add_argument(
        "rig", nargs="?", type=args.InputPath("RIG", text=True), help="rig file or shipped rig name (default: sim-3x3)"
    )
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
    p.add_argument(
        "--force", action="store_true", help="record even if preflight refuses (disk far too slow, too little space)"
    )
    p.add_argument("--no-checksum", action="store_true", help="skip per-frame CRC-32 (saves CPU at high rates)")
    p.add_argument(
        "--buffers",
        type=int,
        metavar="N",
        help="frame buffers per camera (default: a second of frames within a 3 GB budget)",
    )
    p.add_argument("--json", action="store_true", help="print the take's summary as JSON")
    add_quiet(p)
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    rig = load_rig(ns.rig)
    name = check_take_name(ns.take)
    if ns.frames is not None and ns.frames <= 0:
        raise ParameterError(f"--frames must be a positive number of frame sets, got {ns.frames}")
    if ns.seconds is not None and not (ns.seconds > 0 and math.isfinite(ns.seconds)):
        raise ParameterError(f"--seconds must be a positive number of seconds, got {ns.seconds}")
    frames = ns.frames if ns.frames is not None else (round(ns.seconds * rig.fps) if ns.seconds else None)
    sim = list(ns.sim) + ([f"scene={ns.scene}"] if ns.scene else [])

    def say(text: str) -> None:  # above the bar while one is shown (rich redirects stderr meanwhile)
        print(f"rigctl record: {text}", file=sys.stderr, flush=True)

    def show_preflight(report: PreflightReport) -> None:
        refused = not report.ok and not (ns.force and report.forcible)
        for line in report.lines():
            # a refusal is the command's one error line (its need in MB/s included): nothing before it
            if not line.startswith("preflight refuse") and not (refused and line.startswith("data rate")):
                say(line)

    for dest in (ns.out, *ns.dest):  # refused before a frame is taken, not after the manifest says complete
        utf8_path(dest, "--out" if dest is ns.out else "--dest")
    with Progress(f"recording {name}", "frame sets", ns.quiet, total=frames) as bar:
        result = record_take(
            rig,
            name,
            [ns.out, *ns.dest],
            frames=frames,
            sim=sim,
            checksum=not ns.no_checksum,
            buffers_per_camera=ns.buffers,
            force=ns.force,
            progress=bar.fraction,
            catch_interrupt=True,
            say=say,
            on_preflight=show_preflight,
        )
        if result.manifest is None and result.recorder.error is not None:  # nothing was kept: the name is free
            raise result.recorder.error  # inside: a failed take ends with its error line alone, no summary
        bar.close(finished=result.recorder.error is None)  # a take cut short by an error: its line, no summary
    reader = TakeReader(result.folder, skip_damaged=True)  # the summary of what was written
    summary = reader.summary()
    summary["path"] = str(result.folder)
    if ns.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
    if result.recorder.error is not None:
        raise result.recorder.error
    return 0 if result.manifest else 1


def format_summary(s: dict) -> str:
    cams = s["cameras"]
    lines = [
        f"take {s['take']} ({s['status']}): {s['frame_sets']} frame sets, {s['complete_sets']} complete, "
        f"{len(cams)} cameras, {s['format']}",
    ]
    if "data_rate" in s:
        rate = s["data_rate"]
        lines.append(
            f"data rate: {rate_text(rate['camera_bytes_per_s'])} a camera, {rate_text(rate['array_bytes_per_s'])} "
            f"for the array ({rate['bits_per_pixel']:g} bits a pixel)"
        )
    skew = s["skew"]
    lines.append(f"skew within frame sets: p50 {skew['p50_us']} us, p99 {skew['p99_us']} us, max {skew['max_us']} us")
    for name, c in cams.items():
        lost = {
            k: c[k] for k in ("source_drops", "error_frames", "writer_drops", "not_written", "torn_excluded") if c[k]
        }
        lost_text = "".join(f", {k.replace('_', ' ')} {n}" for k, n in lost.items())
        lines.append(f"  {name}: {c['frames']} frames{lost_text}")
    if s.get("end"):
        end = s["end"]
        lines.append(f"ended: {end.get('reason', '')}" + (f": {end['message']}" if end.get("message") else ""))
    for note in s.get("notes", []):
        lines.append(f"note: {note}")
    if "path" in s:
        lines.append(f"written to {s['path']}")
    return "\n".join(lines)
