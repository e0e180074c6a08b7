"""``rigctl process``: a take's frame sets on a Dask cluster (rectify when needed, depth, export)."""

from __future__ import annotations

import argparse
import os
import re
import socket
import struct
import sys
from pathlib import Path

from rigctl.cli import args
from rigctl.cli.args import add_pipeline_options, depth_options, distance, far_distance
from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet
from rigctl.depth.presets import PRESETS
from rigctl.errors import DeviceError
from rigctl.publish import output_folder, refuse_inside
from rigctl.take.framesets import parse_frames

WORKERS_PER_CORE = 4  # local workers beyond this only queue for the cores (and each holds a frame set)
MIN_MEMORY = 256 << 20
_UNITS = {"": 1, "B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "TB": 10**12}
_UNITS.update({"KIB": 1 << 10, "MIB": 1 << 20, "GIB": 1 << 30, "TIB": 1 << 40})


def local_workers(text: str) -> int:
    """1 to 4 local workers a core of this machine (a farm is reached with --scheduler)."""
    most = WORKERS_PER_CORE * (os.cpu_count() or 1)
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got {text!r}") from None
    if not 1 <= n <= most:
        raise argparse.ArgumentTypeError(
            f"{n}: 1 to {most} local workers on this machine ({WORKERS_PER_CORE} a core); use --scheduler for more"
        )
    return n


def memory_limit(text: str) -> str | int:
    """``auto`` or a size (``6GiB``, ``1500MB``, bytes) between 256 MiB and this machine's memory."""
    if text == "auto":
        return text
    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([A-Za-z]*)\s*", text)
    unit = m[2].upper() if m else ""
    if m is None or unit not in _UNITS:
        raise argparse.ArgumentTypeError(f"expected auto or a size such as 6GiB or 1500MB, got {text!r}")
    value = int(float(m[1]) * _UNITS[unit])
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    if not MIN_MEMORY <= value <= total:
        raise argparse.ArgumentTypeError(
            f"{text}: between 256MiB and this machine's memory ({total / (1 << 30):.1f}GiB) per worker"
        )
    return value


PROBE_TIMEOUT_S = 5.0
MAX_HANDSHAKE_BYTES = 1 << 20


def probe_scheduler(url: str, timeout: float = PROBE_TIMEOUT_S) -> None:
    """Refuse, in one line and within ``timeout``, an address that does not answer as a Dask scheduler does:
    on a connection it sends its handshake unasked, a length (8 bytes) and a small message. A silent listener
    would hold the client, and garbage read as a length asked numpy for exabytes."""
    host, _, port = url.removeprefix("tcp://").rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout) as conn:
            conn.settimeout(timeout)
            head = b""
            while len(head) < 8:
                chunk = conn.recv(8 - len(head))
                if not chunk:
                    break
                head += chunk
    except TimeoutError:
        raise DeviceError(f"--scheduler {url}: no answer within {timeout:g} s: not a Dask scheduler") from None
    except OSError as exc:
        raise DeviceError(f"--scheduler {url}: cannot reach it ({exc.strerror or exc})") from None
    except UnicodeError:  # the resolver's IDNA encoding refuses it (a..b, an empty label, a label of 64+)
        raise DeviceError(f"--scheduler {url}: {host!r:.80} is not a host name") from None
    if len(head) < 8:
        raise DeviceError(f"--scheduler {url}: closed the connection without a handshake: not a Dask scheduler")
    (size,) = struct.unpack("<Q", head)
    if not 0 < size <= MAX_HANDSHAKE_BYTES:
        raise DeviceError(f"--scheduler {url}: its first message claims {size:,} bytes: not a Dask scheduler")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "process",
        epilog=examples(
            ("the demo's rectified take on two local workers",
             "rigctl process rigctl-demo/takes/presenter-rectified --out farm --workers 2"),
            ("a take not yet rectified, rectified on the workers; run it again to finish what a stopped run left",
             "rigctl process rigctl-demo/takes/presenter --calibration rigctl-demo/calibration.yaml --out farm2"),
        ),
        help="depth for every frame set of a take on a Dask cluster (local processes or a scheduler)",
        description="Chunks of --chunk consecutive frame sets are Dask tasks (the take's range decided first, "
        "once): rectify (when the take is not rectified: --calibration), depth "
        "and export, written to DIR/depth/<frame>/<camera>.{exr,pfm,png} as rigctl depth writes them, with "
        "DIR/process.json saying which frames are done. Workers read the take from storage they share; run again "
        "to finish what a stopped run left (done frames are skipped unless --redo).",
    )
    p.add_argument("take", type=args.InputPath("TAKE"), metavar="TAKE")
    p.add_argument("--out", type=Path, required=True, metavar="DIR")
    p.add_argument(
        "--calibration",
        type=args.InputPath("--calibration"),
        metavar="C",
        help="calibration.yaml for a take not yet rectified",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a running Dask scheduler")
    where.add_argument(
        "--workers", type=local_workers, default=2, metavar="N", help="local worker processes (default 2)"
    )
    p.add_argument(
        "--memory-limit",
        type=memory_limit,
        default="auto",
        metavar="BYTES",
        help="local workers' memory limit, e.g. 6GiB (default: the bound measured for the take's frame size)",
    )
    p.add_argument("--frames", metavar="A-B", help="frame sets (default: all complete ones)")
    p.add_argument("--cameras", nargs="+", type=args.camera, metavar="CAM", help="cameras to compute (default: all)")
    p.add_argument("--preset", choices=list(PRESETS), default="best")
    p.add_argument("--near", type=distance, metavar="M", help="nearest subject distance (planner range)")
    p.add_argument("--far", type=far_distance, metavar="M", help="farthest subject distance (inf allowed)")
    p.add_argument("--no-key", action="store_true", help="search every pixel (no green-screen key)")
    add_pipeline_options(p)
    p.add_argument("--redo", action="store_true", help="compute frames again even when done")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_quiet(p)
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:

    if not ns.debug:  # Dask's own INFO lines (scheduler, nannies, workers inherit it) only with --debug
        os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "warning")

    from rigctl.farm.run import FarmOptions, Status, process_take, scheduler_url

    refuse_inside(ns.out, ns.take)
    if ns.scheduler:
        probe_scheduler(scheduler_url(ns.scheduler))
    opt = FarmOptions(
        take=ns.take,
        out=ns.out,
        depth=depth_options(ns),
        calibration=ns.calibration,
        frames=parse_frames(ns.frames) if ns.frames else None,
        redo=ns.redo,
        scheduler=scheduler_url(ns.scheduler) if ns.scheduler else None,
        workers=ns.workers,
        memory_limit=ns.memory_limit,
        formats=ns.formats,
    )
    with Progress(f"process {ns.take.name}", "frame sets", ns.quiet) as bar:

        def show(st: Status) -> None:
            # each round's frame sets apart: a widened range computes the take again, it does not double it
            notes = [f"round {st.round}: the take's range was widened"] if st.round > 1 else []
            notes += [f"{st.failed} failed"] if st.failed else []
            bar.update(st.round_finished, st.round_total, "; ".join(notes))

        with output_folder(ns.out, "process"):  # usable, and one run at a time on a folder
            summary = process_take(opt, progress=show)
    if ns.json:
        print(summary.model_dump_json())
    else:
        rng = summary.range
        if rng is not None:
            lo, hi = rng.disparity_range_px
            print(f"take range {lo:.1f}..{hi:.1f} px ({rng.source}); bound hit on {summary.bound_hit_pixels} px in all")
            if summary.search is not None and summary.search.rounds > 1:
                lo, hi = summary.search.state.disparity_range_px
                rounds = summary.search.rounds
                print(f"widened to {lo:.1f}..{hi:.1f} px: every chunk computed again from it ({rounds} rounds)")
        again = ""
        if summary.chunks_recomputed:  # the repeat passes, said apart from the frame sets they computed again
            again = (
                f" ({summary.chunks_recomputed} chunks, {summary.recomputed} frame sets, run again after the range "
                "widened)"
            )
        print(
            f"{summary.computed} frame sets computed in {summary.chunks} chunks{again}, {summary.failed} failed, "
            f"{summary.skipped_done} already done; {summary.frames_per_second:.2f} frames/s; ledger {summary.ledger}"
        )
        for name, err in summary.failed_frames.items():  # what went wrong goes where errors go
            print(f"rigctl process: frame {name} failed: {err}", file=sys.stderr)
    return 1 if summary.failed else 0
