"""``rigctl bench depth``: error against run time, presets and OpenCV baselines measured in the same run."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rigctl.cli import args, bench_record, render
from rigctl.cli.helptext import examples
from rigctl.cli.progress import Progress, add_quiet
from rigctl.errors import ParameterError


def register(sub: argparse._SubParsersAction) -> None:
    depth = ("error against run time of every depth preset and OpenCV", "rigctl bench depth --quick")
    render_pair = ("the renderer's time for a 1080p stereo pair", "rigctl bench render")
    summary = "benchmarks that report error against run time"
    p = sub.add_parser("bench", help=summary, epilog=examples(depth, render_pair))
    what = p.add_subparsers(dest="what", metavar="WHAT")
    d = what.add_parser(
        "depth",
        epilog=examples(
            (
                "every preset and baseline without the ideal presenter, the plot in bench.png",
                "rigctl bench depth --quick --plot bench.png",
            ),
            (
                "time and peak memory of one 960x540 frame set, one camera",
                "rigctl bench depth --size 960x540 --cameras r1c1",
            ),
            (
                "flicker with temporal stabilisation off and on, 4 frame sets a take",
                "rigctl bench depth --video --frames 4",
            ),
        ),
        help="every depth preset and the OpenCV baselines on the simulated presenter, Middlebury Motorcycle and "
        "the stratified light-field scenes, as a light field and as parallel cameras see them (+60 px)",
    )
    d.add_argument("--repeats", type=int, help="runs per method (the median time is kept; default 1)")
    d.add_argument("--plot", type=Path, default=Path("bench-depth.png"), metavar="PNG")
    d.add_argument("--json", action="store_true")
    d.add_argument("--quick", action="store_true", help="without the ideal presenter")
    d.add_argument(
        "--size",
        metavar="WxH",
        help="instead: time and peak memory of one frame set of the ideal presenter scaled to this size (3840x2160)",
    )
    d.add_argument(
        "--video",
        action="store_true",
        help="instead: depth over time on a still and a moving realistic presenter take, temporal stabilisation "
        "off and on (flicker, change error, bad 1.0, time per frame)",
    )
    d.add_argument("--frames", type=int, metavar="N", help="with --video: frame sets per take (default 10)")
    d.add_argument("--preset", help="with --size or --video: the depth preset (default best)")
    d.add_argument(
        "--cameras", nargs="+", type=args.camera, metavar="CAM", help="with --size: cameras to compute (default: all)"
    )
    d.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="with --size: the farm's workers for the real-time factor (default 10)",
    )
    d.add_argument(
        "--fps",
        type=float,
        metavar="FPS",
        help="with --size: the footage's frame rate for the real-time factor (default: the paper's rig's, 25)",
    )
    add_quiet(d)
    d.set_defaults(func=run_depth_bench)
    render.register_bench(what)
    bench_record.register_bench(what)
    p.set_defaults(func=lambda ns: (p.print_help(), 2)[1])


def run_depth_bench(ns: argparse.Namespace) -> int:
    from rigctl.depth.bench import format_table, motorcycle, plot, run_bench, stratified, stratified_shifted
    from rigctl.errors import ParameterError
    from rigctl.simulated_presenter import presenter

    check_bench_options(ns)
    if ns.size:
        return run_size_bench(ns)
    if ns.video:
        return run_video_bench(ns)
    ns.repeats = 1 if ns.repeats is None else ns.repeats
    if ns.repeats < 1:
        raise ParameterError(f"--repeats must be at least 1, got {ns.repeats}")
    with Progress("bench depth", "runs", ns.quiet) as bar:
        datasets = ([] if ns.quick else [presenter(True)]) + [presenter(False), motorcycle(), *stratified()]
        datasets += stratified_shifted()  # the scenes as a light field and as parallel cameras see them
        result = run_bench(datasets, repeats=ns.repeats, progress=bar.update)
    plot(result, ns.plot)
    if ns.json:
        print(json.dumps(result.to_json(), default=float))
    else:
        print(format_table(result))
        print(f"plot: {ns.plot}")
    return 0


# each option and the benches that read it (None: the preset table, neither --size nor --video)
APPLIES = {
    "repeats": (None,), "quick": (None,), "frames": ("--video",), "preset": ("--size", "--video"),
    "cameras": ("--size",), "workers": ("--size",), "fps": ("--size",),
}  # fmt: skip


def check_bench_options(ns: argparse.Namespace) -> None:
    """One bench at a time, and no option the chosen bench would ignore (``--video`` with ``--size`` once ran the
    size bench alone; ``--repeats 0`` with ``--size`` was accepted)."""
    if ns.size and ns.video:
        raise ParameterError("--size and --video are two different benches: give one of them")
    mode = "--size" if ns.size else "--video" if ns.video else None
    for name, modes in APPLIES.items():
        given = getattr(ns, name)
        if given is not None and given is not False and mode not in modes:  # 0 is given: not `in (None, False)`
            where = " or ".join(m or "the preset table (without --size and --video)" for m in modes)
            raise ParameterError(f"--{name} applies to {where}, not to {mode or 'the preset table'}")


def check_depth_bench_memory(size: tuple[int, int], cameras: int, free: int | None) -> None:
    """Refuse a size whose frame set would not fit in ``free`` bytes: the worker bound of ``rigctl process``
    (measured per camera pixel), as ``bench render`` refuses its own (no check without a figure)."""
    from rigctl.farm.run import worker_memory_bytes

    w, h = size
    need = worker_memory_bytes(w, h, cameras)
    if free is not None and need > free:
        raise ParameterError(
            f"--size {w}x{h}: one frame set of {cameras} cameras needs about {need / 2**30:.1f} GB, "
            f"{free / 2**30:.1f} GB available"
        )


def run_size_bench(ns: argparse.Namespace) -> int:
    """One frame set at the given size in a fresh process: seconds and peak resident memory."""
    import functools

    from rigctl.farm.membench import format_speed, measure_size, parse_size, speed_summary
    from rigctl.rig import load_rig
    from rigctl.simulated_presenter import presenter

    w, h = parse_size(ns.size)
    ns.workers = 10 if ns.workers is None else ns.workers
    ns.preset = ns.preset or "best"
    if ns.workers < 1:
        raise ParameterError(f"--workers must be at least 1, got {ns.workers}")
    fps = ns.fps if ns.fps is not None else load_rig("bmd-micro-studio-4k-3x3").fps
    if not 0 < fps <= 1000:
        raise ParameterError(f"--fps must be in (0, 1000], got {ns.fps}")
    cams = tuple(ns.cameras) if ns.cameras else None
    check_depth_bench_memory((w, h), len(cams) if cams else 9, render._available_memory())
    r = measure_size(functools.partial(presenter, True), w, h, ns.preset, cams)
    t = r["timings_s"]
    r["fps"], r["workers"] = fps, ns.workers
    cpu = (r["cpu_seconds"], r["sgbm"]["cpu_seconds"])
    r["summary"] = speed_summary(
        t["depth"], t["write"], r["stages_s"], r["sgbm"]["seconds"], fps, ns.workers, cpu, t["write_cpu"]
    )
    print(json.dumps(r) if ns.json else format_speed(r))
    return 0


def run_video_bench(ns: argparse.Namespace) -> int:
    from rigctl.depth.presets import PRESETS
    from rigctl.depth.video_bench import VideoTake, format_video_table, plot_video, run_video_bench
    from rigctl.errors import ParameterError
    from rigctl.simulated_presenter import presenter_video

    ns.frames = 10 if ns.frames is None else ns.frames
    ns.preset = ns.preset or "best"
    if not 2 <= ns.frames <= 1000:
        raise ParameterError(f"--frames: a video bench needs 2 to 1000 frame sets per take, got {ns.frames}")
    if ns.preset not in PRESETS:
        raise ParameterError(f"--preset: unknown preset {ns.preset!r} (presets: {', '.join(PRESETS)})")
    plot_path = ns.plot if ns.plot != Path("bench-depth.png") else Path("bench-depth-video.png")
    with Progress("bench depth --video", "frames", ns.quiet) as bar:
        takes = [
            VideoTake("still", presenter_video(False, ns.frames), still=True),
            VideoTake("moving", presenter_video(True, ns.frames), still=False),
        ]
        result = run_video_bench(takes, ns.preset, progress=bar.update)
    plot_video(result, plot_path)
    if ns.json:
        print(json.dumps(result.to_json()))
    else:
        print(format_video_table(result))
        print(f"plot: {plot_path}")
    return 0
