"""``rigctl demo``: the whole chain on the simulated rig, with a Markdown report and its figures.

plan -> record a calibration take -> calibrate -> record a presenter take -> rectify -> depth -> benchmark ->
report. Every step runs the same code as its own command."""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from rigctl.diskspace import FreeSpace, check_free_space
from rigctl.errors import OutputError, ParameterError
from rigctl.publish import OutputLock, prepare_output, publish_png, publish_text, utf8_path

Say = Callable[[str], None]
MARKER = ".rigctl-demo"
# what a finished demo's folder holds, with a quarter to spare (0.88 GB measured in session 26: the calibration
# take 0.7 GB, the presenter takes, the depth outputs; tests/integration/test_depth.py holds a demo to it)
DEMO_BYTES = 1_100_000_000


def _montage(folder: Path, names: list[str], out: Path) -> Path:
    """The per-camera depth previews in the rig's layout (seen from behind)."""
    tiles = {}
    for n in names:
        img = cv2.imread(str(folder / f"{n}.png"))
        if img is not None:
            tiles[n] = cv2.resize(img, (img.shape[1] // 2, img.shape[0] // 2), interpolation=cv2.INTER_AREA)
    rows = sorted({int(n[1 : n.index("c")]) for n in tiles})
    cols = sorted({int(n[n.index("c") + 1 :]) for n in tiles})
    h, w = next(iter(tiles.values())).shape[:2]
    canvas = np.zeros((len(rows) * h, len(cols) * w, 3), np.uint8)
    for n, img in tiles.items():
        r, c = rows.index(int(n[1 : n.index("c")])), cols.index(int(n[n.index("c") + 1 :]))
        canvas[r * h : (r + 1) * h, c * w : (c + 1) * w] = img
        cv2.putText(canvas, n, (c * w + 6, r * h + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1)
    publish_png(out, canvas)
    return out


@contextmanager
def prepare_folder(out: Path, fresh: bool) -> Iterator[Path]:
    """Make ``out`` the demo's empty folder, marked as an unfinished demo until its report is written, held
    under this run's lock for the length of the ``with``: a second demo on the same folder is refused in one
    line before it looks at, let alone clears, what the first is writing."""
    utf8_path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: is a file, not a folder")
    prepare_output(out)
    with OutputLock(out, "demo"):
        entries = list(out.iterdir())
        if entries:
            # an unfinished demo (a step failed or was interrupted) is replaced without asking, a finished demo's
            # figures only with --fresh, and a folder that holds no demo never (it is somebody's work). The
            # folder itself stays: it holds the lock
            if not (out / MARKER).exists():
                raise ParameterError(
                    f"{out}: exists, is not empty and holds no demo (no {MARKER}): choose another --out "
                    "(--fresh replaces only a demo's folder)"
                )
            unfinished = not (out / "report.md").exists()
            if not fresh and not unfinished:
                raise ParameterError(f"{out}: exists and is not empty (choose another --out, or --fresh to replace it)")
        check_demo_room(out)  # before anything is cleared or written
        if entries:
            # the report first and the marker last: a run killed while clearing leaves an unfinished demo, which
            # the next run replaces, never a "finished" one missing its figures or a folder with no marker
            for p in sorted(entries, key=lambda p: (p.name != "report.md", p.name == MARKER)):
                shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
        publish_text(out / MARKER, "rigctl demo: until report.md is written, the next demo here replaces this folder\n")
        yield out


def check_demo_room(out: Path, free_space: FreeSpace | None = None) -> None:
    """Refuse in one line (exit 4) a destination without room for a whole demo, counting as free what the demo
    already in ``out`` takes (it is replaced); ``free_space`` injected by tests."""
    replaced = _freed_bytes(out) if (out / MARKER).is_file() else 0
    what = "the demo's takes, calibration, depth and report"
    check_free_space(out, max(0, DEMO_BYTES - replaced), what, free_space)


def _freed_bytes(folder: Path) -> int:
    """The disk space removing ``folder`` gives back, as far as it can be told: the blocks its files hold (not
    their apparent sizes: a sparse file frees less), each file once (hard links), symlinks not followed."""
    seen, total = set(), 0
    for root, _dirs, names in os.walk(folder):
        for name in names:
            try:
                st = os.lstat(os.path.join(root, name))
            except OSError:
                continue
            if (st.st_dev, st.st_ino) not in seen:
                seen.add((st.st_dev, st.st_ino))
                total += st.st_blocks * 512
    return total


def run_demo(out: Path, say: Say, progress_factory: Callable[[str, str], Any], fresh: bool = False) -> Path:
    """The whole chain into ``out``, held under this run's lock on the folder; returns the report.
    ``progress_factory(label, unit)`` gives each step's progress: a context manager with ``update(done, total,
    what)`` and ``steps(done, total)`` (the CLI's rich display)."""
    with prepare_folder(out, fresh):
        return _run_demo(out, say, progress_factory)


def _run_demo(out: Path, say: Say, progress_factory: Callable[[str, str], Any]) -> Path:
    from rigctl.calib.report import format_table as calib_table
    from rigctl.calib.report import write_plots
    from rigctl.calib.run import calibrate
    from rigctl.capture.recording import record_take
    from rigctl.depth.bench import better, comparisons, motorcycle, plot, run_bench
    from rigctl.depth.bench import format_table as bench_table
    from rigctl.depth.run import DepthOptions, run_depth
    from rigctl.planning.report import plan_rig
    from rigctl.planning.text import format_plan
    from rigctl.rectification.rectify import rectify_take
    from rigctl.registry import simulated_burnin_box
    from rigctl.render.demo import novel_views_section
    from rigctl.rig import load_rig
    from rigctl.simulated_presenter import presenter

    takes = out / "takes"
    timings: dict[str, float] = {}
    t_all = time.perf_counter()

    def step(name: str) -> float:
        say(f"== {name}")
        return time.perf_counter()

    rig = load_rig("sim-3x3")

    def record(take: str, frames: int, *sim: str) -> None:
        # a planned take of a few frame sets: preflight says go whenever memory holds it, on any disk
        with progress_factory(f"recording {take}", "frame sets") as bar:
            result = record_take(
                rig, take, [takes], frames=frames, sim=["deterministic=true", *sim],
                progress=lambda share: bar.update(round(share * frames), frames),
            )  # fmt: skip
        say(f"preflight {result.preflight.outcome}: " + "; ".join(v.message for v in result.preflight.verdicts))
        if result.recorder.error is not None:
            raise result.recorder.error

    t0 = step("plan: equations (1) and (2) for the paper's rig geometry, subject 1 m deep")
    plan = plan_rig(rig, subject_depth_m=1.0)
    plan_text = format_plan(plan, rig)
    say(plan_text)
    near, far = plan.near_m, plan.far_m
    timings["plan"] = time.perf_counter() - t0

    t0 = step("record a calibration take (ChArUco board, 24 poses)")
    record("calibration", 24, "scene=charuco", "board_poses=24")
    timings["record calibration take"] = time.perf_counter() - t0

    t0 = step("calibrate all nine cameras jointly")
    with progress_factory("calibrating", "views") as bar:
        result = calibrate(takes / "calibration", progress=lambda what, done, total: bar.update(done, total, what))
    cal_path = out / "calibration.yaml"
    result.calibration.save(cal_path)
    cal_plots = write_plots(result, out / "calibration")
    say(calib_table(result))
    for line in result.diagnosis:
        say(f"diagnosis: {line}")
    timings["calibrate"] = time.perf_counter() - t0

    t0 = step(f"record a presenter take (subject from {near:.2f} m)")
    record("presenter", 3, f"subject_distance_m={near + 0.05:.3f}", "motion_states=3")  # hands 5 cm inside near
    timings["record presenter take"] = time.perf_counter() - t0

    t0 = step("rectify the presenter take with the calibration")
    with progress_factory("rectifying", "frames") as bar:
        rect = rectify_take(takes / "presenter", cal_path, takes / "presenter-rectified", bar.steps)
    timings["rectify"] = time.perf_counter() - t0

    t0 = step(f"depth for all nine cameras (frame set 0, planned range {near:.2f}-{far:.2f} m, keyed)")
    with progress_factory("depth", "cameras") as bar:
        depth = run_depth(
            takes / "presenter-rectified", out / "depth", DepthOptions(near_m=near, far_m=far), [0],
            ("exr", "pfm", "png"), progress=bar.update,  # every output: the previews make the montage
        )  # fmt: skip
    frame = next(iter(depth.frames.values()))
    montage = _montage(out / "depth" / "000000", rig.camera_names, out / "depth-previews.png")
    timings["depth"] = time.perf_counter() - t0

    t0 = step("error against run time: presets and OpenCV baselines in one run")
    with progress_factory("bench", "runs") as bar:
        bench = run_bench([presenter(False), motorcycle()], progress=bar.update)
    bench_plot = plot(bench, out / "error-vs-time.png")
    say(bench_table(bench))
    timings["bench"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all

    rep = result.report
    res = rep.rectification_residuals
    truth_rows = [c.truth or {} for c in rep.cameras.values()]
    lines = [
        "# rigctl demo: the simulated 3x3 rig, end to end",
        "",
        "![depth previews, red near, blue far](depth-previews.png)",
        "",
        "![error against run time](error-vs-time.png)",
        "",
        "## Figures",
        "",
        f"- Calibration: RMS {rep.rms_px:.4f} px over {len(rep.cameras)} cameras; "
        + (
            f"worst camera against the truth: centre {max(t['centre_mm'] for t in truth_rows):.3f} mm, "
            f"rotation {max(t['rotation_deg'] for t in truth_rows):.4f} deg."
            if truth_rows and all(truth_rows)
            else ""
        ),
    ]
    pooled_rows = (
        [
            (res.vertical_between_horizontal_neighbours, "vertical disparity between horizontal neighbours"),
            (res.horizontal_between_vertical_neighbours, "horizontal disparity between vertical neighbours"),
        ]
        if res
        else []
    )
    for pooled, label in pooled_rows:
        lines.append(
            f"- Rectification, held-out corners, {label}: RMS {pooled.net.rms:.3f} px net of camera "
            f"placement ({pooled.raw.rms:.3f} px raw)."
        )
    fr_truth = [t for cam in frame.cameras if (t := frame.truth(cam)) is not None]
    subject = max(1, sum(t.pixels for t in fr_truth))
    missed = sum(t.missed_fg_pct * t.pixels for t in fr_truth) / subject
    if fr_truth:
        lines.append(
            "- Depth on the demo's own rectified take (its truth is in the true calibration's geometry): mean bad "
            f"1.0 {np.mean([t.bad_1_0 for t in fr_truth]):.2f} %, "
            f"bad 2.0 {np.mean([t.bad_2_0 for t in fr_truth]):.2f} %; over all cameras, depth where the truth "
            f"has none on {100 * sum(t.false_fg_pixels for t in fr_truth) / subject:.3f} % as many pixels "
            f"as the subject has, none on {missed:.3f} % of the subject."
        )
    lines.append(
        f"- Keyed background left out: {frame.keyed_background_share:.0%} of pixels; disparity levels left out "
        f"by the planned range: {frame.levels_skipped_by_plan:.0f}; planner bound hit on "
        f"{frame.bound_hit_pixels} px."
    )
    for c in comparisons(bench):
        lines.append(
            f"- {c.dataset}: preset {c.preset} against {c.baseline}: bad 1.0 "
            f"{better(c.bad1_improvement)}, {c.time_ratio:.2f}x the time."
        )
    lines += [
        "",
        *novel_views_section(
            takes / "presenter-rectified", out / "depth", out, simulated_burnin_box(takes / "presenter", rig.width_px)
        ),
        "## Plan",
        "",
        "```",
        plan_text,
        "```",
        "",
        "## Calibration",
        "",
        "```",
        calib_table(result),
        "```",
        "",
        *(f"![{p.stem}]({p.name})" for p in cal_plots),
        "",
        "## Depth benchmark",
        "",
        "```",
        bench_table(bench),
        "```",
        "",
        "## Steps",
        "",
        "| step | seconds |",
        "|---|---|",
        *(f"| {k} | {v:.1f} |" for k, v in timings.items()),
        "",
        f"Rectified {rect.frames} frames at f = {rect.focal_px:.1f} px. Takes: `takes/`; calibration: "
        "`calibration.yaml`; depth: `depth/` (EXR, PFM, PNG, report.json).",
    ]
    report = out / "report.md"
    publish_text(out / "timings.json", json.dumps(timings, indent=1))
    publish_text(report, "\n".join(lines) + "\n")  # last: report.md marks the demo finished
    _ = (montage, bench_plot)
    return report
