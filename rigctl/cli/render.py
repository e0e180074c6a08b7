"""``rigctl render``: novel views from colour + disparity, leave-one-out scoring; ``rigctl bench render``."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rigctl.cli import args
from rigctl.cli.args import distance
from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet
from rigctl.diskspace import check_free_space
from rigctl.errors import OutputError, ParameterError
from rigctl.publish import check_creatable, kind, output_folder, utf8_path

if TYPE_CHECKING:
    from rigctl.render.views import LeaveOneOutRow


def position(text: str) -> tuple[float, float]:
    """``COL,ROW`` in grid units (fractional allowed)."""
    try:
        col, row = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected COL,ROW in grid units such as 1.5,1, got {text!r}") from None
    if not (math.isfinite(col) and math.isfinite(row)):
        raise argparse.ArgumentTypeError(f"position must be finite, got {text!r}")
    return col, row


def size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH such as 1920x1080, got {text!r}") from None
    if not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"size must be 16..16384 pixels each way, got {text!r}")
    return w, h


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "render",
        epilog=examples(
            ("the view between the centre camera and its right neighbour, from the simulator's true disparity",
             "rigctl render takes/ideal --disparity takes/ideal/truth/disparity --at 1.5,1 --out views"),
            ("an eye pair 63 mm apart at the centre camera, from the demo's depth",
             "rigctl render rigctl-demo/takes/presenter-rectified --disparity rigctl-demo/depth --at 1,1 "
             "--stereo 0.063 --out stereo"),
            ("each camera rendered from the others and scored against its own picture",
             "rigctl render rigctl-demo/takes/presenter-rectified --disparity rigctl-demo/depth --leave-one-out"),
        ),
        help="novel views from colour + disparity (DIBR), and leave-one-out scoring of a disparity",
        description="Renders views anywhere in the array plane from the nearest cameras' colour and disparity: "
        "OUT/<frame>/c<COL>r<ROW>.png and .exr (RGBA, alpha from the key; _L/_R with --stereo; path_NNNN with "
        "--path). --leave-one-out renders each camera from the others and scores it against its own image "
        "(PSNR, SSIM on the keyed subject).",
    )
    args.add_views_input(p)
    p.add_argument("--at", type=position, action="append", metavar="COL,ROW", help="view position (grid units)")
    p.add_argument("--stereo", type=distance, metavar="IPD_M", help="an eye pair this far apart (metres)")
    p.add_argument("--path", type=position, nargs="+", metavar="COL,ROW", help="a sequence along these positions")
    p.add_argument("--steps", type=int, help="views along --path (default 9, at most 10000)")
    p.add_argument("--leave-one-out", action="store_true", help="score each camera rendered from the others")
    p.add_argument(
        "--cameras",
        nargs="+",
        action="extend",
        type=args.camera,
        metavar="CAM",
        help="cameras for --leave-one-out (default: all)",
    )
    p.add_argument("--frames", metavar="A-B", help="frame sets (default: every complete one with a disparity)")
    p.add_argument("--out", type=Path, metavar="OUT")
    p.add_argument("--json", action="store_true")
    add_quiet(p)
    p.set_defaults(func=run)


def register_bench(what: argparse._SubParsersAction) -> None:
    b = what.add_parser(
        "render",
        epilog=examples(
            ("a 1080p stereo pair from the four nearest cameras, the median of 10", "rigctl bench render"),
            ("a quicker run at 960x540, as JSON", "rigctl bench render --size 960x540 --repeats 3 --json"),
        ), help="time a stereo pair from the four nearest cameras; quality on the simulated take"
    )
    b.add_argument("--size", type=size, default=(1920, 1080), metavar="WxH", help="default 1920x1080")
    b.add_argument("--repeats", type=int, default=10, help="timed pairs, 1 to 1000 (the median is kept)")
    b.add_argument("--json", action="store_true")
    add_quiet(b)
    b.set_defaults(func=run_bench)


def simulator_hooks(source: Path, width: int) -> tuple[Any, Any]:
    """The simulator's truth views and burn-in window for a simulated take (both None otherwise)."""
    from rigctl import registry

    if not (source / "take.yaml").exists():
        return None, None
    box = registry.simulated_burnin_box(source, width)

    def truth(col: float, row: float) -> Any:
        return registry.simulated_view(source, col, row)

    return (truth if box is not None else None), box


def leave_one_out_report(
    source: Path, disparity: Path, frames: Sequence[int] | None, cameras: list[str] | None
) -> list[LeaveOneOutRow]:
    """Leave-one-out rows for ``rigctl depth --check``: the cameras just computed, scored from the others."""
    from rigctl.render.inputs import RenderInput
    from rigctl.render.views import leave_one_out

    inp = RenderInput(source, disparity)
    numbers = inp.select(range(min(frames), max(frames) + 1) if frames else None)
    box = simulator_hooks(source, inp.frame(numbers[0]).shape[1])[1]
    return leave_one_out(inp, numbers, cameras, box)


def _check_out(out: Path) -> None:
    """Refuse an output folder that cannot be made, before any input is read (without making it yet: a run
    that then fails on its input leaves nothing behind)."""
    utf8_path(out)
    if out.exists():
        if not out.is_dir():  # a file, or a device such as /dev/null: exit 4 like any unusable destination
            raise OutputError(f"--out {out}: cannot make the output folder: it is {kind(out.stat().st_mode)}")
        return
    check_creatable(out, noun="folder")


def run(ns: argparse.Namespace) -> int:
    from rigctl.render.inputs import RenderInput
    from rigctl.render.views import eyes_for, format_table, leave_one_out, path_positions, render_views, views_bytes
    from rigctl.take.framesets import parse_frames

    modes = sum(bool(x) for x in (ns.at, ns.path, ns.leave_one_out))
    if modes != 1:
        raise ParameterError("give one of --at COL,ROW, --path COL,ROW COL,ROW ... or --leave-one-out")
    if not ns.leave_one_out and ns.out is None:
        raise ParameterError("--out OUT is required to write views")
    if ns.stereo is not None and ns.leave_one_out:
        raise ParameterError("--stereo applies to --at and --path, not --leave-one-out")
    if ns.cameras and not ns.leave_one_out:
        raise ParameterError("--cameras applies to --leave-one-out (a view's sources are its nearest cameras)")
    if ns.cameras and len(set(ns.cameras)) < len(ns.cameras):
        twice = sorted({c for c in ns.cameras if ns.cameras.count(c) > 1})
        raise ParameterError(f"--cameras names {', '.join(twice)} more than once")
    if ns.steps is not None and not ns.path:
        raise ParameterError("--steps applies to --path")
    if ns.out is not None and ns.leave_one_out:
        raise ParameterError("--leave-one-out writes no images, only scores: leave out --out (--json for a file)")
    if ns.out is not None and not ns.leave_one_out:
        _check_out(ns.out)
    points = path_positions(ns.path, 9 if ns.steps is None else ns.steps) if ns.path else []
    inp = RenderInput(ns.input, ns.disparity)
    numbers = inp.select(parse_frames(ns.frames) if ns.frames else None)
    first = inp.frame(numbers[0])
    truth, box = simulator_hooks(ns.input, first.shape[1])
    if ns.leave_one_out:
        with Progress(f"leave-one-out {ns.input.name}", "views", ns.quiet) as bar:
            rows = leave_one_out(inp, numbers, ns.cameras, box, bar.update)
        print(json.dumps({"leave_one_out": rows}) if ns.json else format_table(rows))
        return 0
    if ns.path:

        def eyes(frame: Any) -> list[Any]:
            return [e for i, (c, r) in enumerate(points) for e in eyes_for(frame, c, r, ns.stereo, f"path_{i:04d}")]
    else:

        def eyes(frame: Any) -> list[Any]:
            return [e for c, r in ns.at for e in eyes_for(frame, c, r, ns.stereo)]

    wanted = eyes(first)
    for eye in wanted:  # positions no camera sees are refused before the output folder is made
        first.position(eye.col, eye.row)
    count, (height, width) = len(wanted) * len(numbers), first.shape
    with output_folder(ns.out, "render"):  # locked for this run; an interrupted run's leftovers removed
        # the disk is not filled halfway through (refused, the folder made for it is removed again)
        check_free_space(ns.out, views_bytes(count, width, height), f"{count} views of {width}x{height} (PNG + EXR)")
        with Progress(f"render {ns.input.name}", "views", ns.quiet) as bar:
            views = render_views(inp, numbers, eyes, ns.out, truth, box, bar.update)
    if ns.json:
        print(json.dumps({"views": views}))
        return 0
    for r in views:
        t = r.get("against_truth")
        vs = (
            f", against the simulator's view: PSNR {t['psnr_db']:.2f} dB, SSIM {t['ssim']:.4f}, "
            f"IV-PSNR {t['ivpsnr_db']:.2f} dB"
            if t
            else ""
        )
        print(f"{r['frame']}/{r['view']} at {r['col']:g},{r['row']:g} from {' '.join(r['sources'])}{vs}")
    print(f"wrote {len(views)} view(s) to {ns.out}")
    return 0


MAX_REPEATS = 1000


def run_bench(ns: argparse.Namespace) -> int:
    from rigctl.render.bench import bench_render, format_bench
    from rigctl.simulated_presenter import presenter_render

    if not 1 <= ns.repeats <= MAX_REPEATS:  # 1,000 pairs is a minute at 4K; more only runs until killed
        raise ParameterError(f"--repeats must be 1 to {MAX_REPEATS}, got {ns.repeats}")
    check_bench_memory(ns.size, _available_memory())
    with Progress("bench render", "stages", ns.quiet) as bar:
        result = bench_render(presenter_render(), ns.size, ns.repeats, bar.update)
    print(json.dumps(result) if ns.json else format_bench(result))
    return 0


# nine cameras resampled to float RGB, key and disparity (20 bytes a pixel each), their texels, disparity and
# samples (13), two eyes' output and scratch: about 320 bytes per pixel of the size asked for (measured: 0.8 GB
# in all at 1920x1080)
BENCH_BYTES_PER_PIXEL = 320


def check_bench_memory(size: tuple[int, int], free: int | None) -> None:
    """Refuse a benchmark size whose nine cameras would not fit in ``free`` bytes (no check without it)."""
    w, h = size
    need = BENCH_BYTES_PER_PIXEL * w * h + (1 << 29)
    if free is not None and need > free:
        raise ParameterError(
            f"--size {w}x{h}: needs about {need / 2**30:.1f} GB (nine cameras in float and as texels), "
            f"{free / 2**30:.1f} GB available"
        )


def _available_memory() -> int | None:
    """MemAvailable from /proc/meminfo in bytes (None where there is none)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None
