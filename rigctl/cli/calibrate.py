"""``rigctl calibrate``: joint calibration of every camera from a take or a folder of frame sets."""

from __future__ import annotations

import argparse
import json
import os
import stat
import sys
from pathlib import Path

from rigctl.calib import CHESSBOARD_CORNERS, CHESSBOARD_SQUARE
from rigctl.cli import args
from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet
from rigctl.errors import CalibrationError, OutputError, ParameterError
from rigctl.publish import check_creatable, check_output_file, kind, utf8_path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "calibrate",
        epilog=examples(
            ("the demo's ChArUco take: every camera jointly, with the report's plots beside calibration.yaml",
             "rigctl calibrate rigctl-demo/takes/calibration --out calibration.yaml"),
            ("a board take recorded by rigctl record's example, also for OpenCV and COLMAP",
             "rigctl calibrate takes/board --out board-calibration.yaml --opencv opencv.yaml --colmap colmap"),
        ),
        help="calibrate all cameras jointly from a board take or a folder of frame sets",
        description="INPUT is a take, a folder of frame sets (<frame>/<camera>.png) or a folder of images named "
        "<camera><frame>.png (left01.jpg, right01.jpg: a stereo pair). Corners are detected with sub-pixel "
        "refinement; all cameras are solved jointly (OpenCV 5 multiview calibration, then a bundle adjustment); "
        "views far above the median error are rejected and named; the result is cross-validated on two halves "
        "and its rectification residuals measured on held-out frames. A take that cannot constrain a "
        "calibration ends with a diagnosis naming the camera and what to shoot, and nothing is written.",
    )
    p.add_argument("input", type=args.InputPath("INPUT"), metavar="INPUT")
    p.add_argument("--out", type=Path, required=True, metavar="FILE", help="calibration.yaml to write")
    target = p.add_mutually_exclusive_group()
    target.add_argument(
        "--board", type=args.InputPath("--board"), metavar="FILE", help="board description (rigctl board writes one)"
    )
    target.add_argument("--chessboard", metavar="CxR", help="a plain chessboard of C x R inner corners")
    lo, hi = CHESSBOARD_SQUARE
    p.add_argument(
        "--square",
        type=float,
        default=1.0,
        help=f"chessboard square side, {lo:g} to {hi:g} in the unit the calibration is to be in (metres, millimetres; "
        "default 1: one square)",
    )
    p.add_argument(
        "--subpix-window", type=int, default=0, metavar="PX", help="chessboard corner refinement half-window (0: auto)"
    )
    p.add_argument("--distortion", choices=("k1k2", "k1k2k3", "full"), default="k1k2", help="lens model (default k1k2)")
    p.add_argument("--reject", type=float, default=2.5, metavar="X", help="reject views above X times the median error")
    p.add_argument("--opencv", type=Path, metavar="FILE", help="also write OpenCV FileStorage YAML")
    p.add_argument("--colmap", type=Path, metavar="DIR", help="also write a COLMAP text model (with rigs.txt)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots next to --out")
    p.add_argument("--force", action="store_true", help="write the calibration even when the diagnosis finds problems")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    add_quiet(p)
    p.set_defaults(func=run)


def run(ns: argparse.Namespace) -> int:
    from rigctl.calib.detect import Chessboard, Target, load_target
    from rigctl.calib.export import write_colmap, write_opencv_yaml
    from rigctl.calib.report import format_table, write_plots
    from rigctl.calib.run import Options, calibrate

    # the outputs are written after corner detection and the solve (minutes): proven writable first
    check_output_file(ns.out)
    if ns.opencv:
        check_output_file(ns.opencv, "--opencv")
    if ns.colmap:
        utf8_path(ns.colmap, "--colmap")
        if ns.colmap.exists() and not ns.colmap.is_dir():
            raise OutputError(f"--colmap {ns.colmap}: is {kind(ns.colmap.stat().st_mode)}, not a folder")
        check_creatable(ns.colmap, "--colmap", noun="folder")
    refuse_outputs_over_inputs(ns)
    if ns.chessboard:
        try:
            cols, rows = (int(v) for v in ns.chessboard.lower().split("x"))
        except ValueError:
            raise ParameterError(f"--chessboard {ns.chessboard!r}: expected inner corners such as 9x6") from None
        if not all(CHESSBOARD_CORNERS[0] <= v <= CHESSBOARD_CORNERS[1] for v in (cols, rows)):
            raise ParameterError(
                f"--chessboard {ns.chessboard}: must be {CHESSBOARD_CORNERS[0]} to {CHESSBOARD_CORNERS[1]} inner "
                "corners a side (such as 9x6)"
            )
        if ns.subpix_window < 0:
            raise ParameterError(f"--subpix-window {ns.subpix_window}: must be >= 0 (0: auto)")
        lo, hi = CHESSBOARD_SQUARE
        if not lo <= ns.square <= hi:  # NaN fails too
            raise ParameterError(
                f"--square {ns.square:g}: must be {lo:g} to {hi:g} (the square's side in metres, millimetres or "
                "squares: 0.025 or 25 for 25 mm)"
            )
        target: Target | None = Chessboard(cols, rows, ns.square, ns.subpix_window)
    elif ns.board:
        target = load_target(ns.board)
    else:
        target = None
    if not ns.reject > 1:
        raise ParameterError(f"--reject must be above 1 (times the median view error), got {ns.reject}")
    log = (lambda m: print(m, file=sys.stderr)) if not ns.json else None
    with Progress(f"calibrating {ns.input.name}", "views", ns.quiet) as bar:
        result = calibrate(
            ns.input,
            target,
            Options(model=ns.distortion, reject_factor=ns.reject),
            progress=lambda what, done, total: bar.update(done, total, what),
            log=log,
        )
    report = result.report
    problems = result.diagnosis
    if ns.json:
        print(json.dumps(report.as_dict(), default=float))
    else:
        print(format_table(result))
    for line in problems:
        print(f"diagnosis: {line}", file=sys.stderr)
    if problems and not ns.force:
        raise CalibrationError(
            f"calibration not written to {ns.out}: {len(problems)} problem(s) found "
            "(see the diagnosis; --force writes it)"
        )
    result.calibration.save(ns.out)
    written = [ns.out]
    if not ns.no_plots:
        written += write_plots(result, ns.out.with_suffix(""))
    if ns.opencv:
        write_opencv_yaml(result.calibration, ns.opencv)
        written.append(ns.opencv)
    if ns.colmap:
        written += write_colmap(result.calibration, ns.colmap)
    if not ns.json:
        print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _input_files(folder: Path, depth: int = 2) -> list[Path]:
    """The files calibrate may read from its input: a take's (``take.yaml``, ``cameras/``, ``truth/``) or an image
    folder's (``<frame>/<camera>.png``, ``<camera><frame>.png``), at most ``depth`` folders down, through
    symlinked folders as the readers go; nothing is opened (a FIFO among them is the reader's to refuse)."""
    try:
        entries = list(folder.iterdir()) if folder.is_dir() else [folder]
    except OSError:
        return []  # unreadable: the reader names it
    files = []
    for p in entries:
        if p.is_dir() and depth > 1 and p != folder:
            files += _input_files(p, depth - 1)
        else:
            files.append(p)
    return files


def refuse_outputs_over_inputs(ns: argparse.Namespace) -> None:
    """Refuse, before any work, an output that is one of calibrate's inputs (an input picture, a take's file, the
    --board file): compared as files (device and inode, as os.path.samefile), so a symlink or a hard link to an
    input, or a path spelt another way, is caught too. The plots beside --out count as outputs."""
    read: dict[tuple[int, int], Path] = {}
    for p in [*_input_files(ns.input), *([ns.board] if ns.board else [])]:
        try:
            st = os.stat(p)
        except OSError:
            continue  # missing, a loop: the reader names it
        if stat.S_ISREG(st.st_mode):
            read.setdefault((st.st_dev, st.st_ino), p)
    outputs = [("--out", ns.out)]
    if not ns.no_plots:
        stem = ns.out.with_suffix("")
        outputs += [("--out's plot", stem.with_name(f"{stem.name}_{k}.png")) for k in ("coverage", "residuals")]
    if ns.opencv:
        outputs.append(("--opencv", ns.opencv))
    for what, out in outputs:
        try:
            st = os.stat(out)
        except OSError:
            continue  # not there yet: no input
        source = read.get((st.st_dev, st.st_ino))
        if source is not None:
            role = "the --board file" if ns.board and source == ns.board else f"an input file of {ns.input}"
            raise ParameterError(f"{what} {out}: is {source}, {role}: calibrate would write over what it reads")
