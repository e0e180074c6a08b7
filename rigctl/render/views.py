"""Novel views written to disk and leave-one-out scoring, frame by frame."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import NotRequired, TypedDict

import cv2
import numpy as np
import OpenEXR
from numpy.typing import NDArray

from rigctl.errors import OutputError, ParameterError, RigctlError, TakeError
from rigctl.exr import picture, picture_attributes, write_exr
from rigctl.layout import inside
from rigctl.publish import publish_png
from rigctl.render.inputs import F32, FrameViews, RenderInput
from rigctl.render.score import Score, full_frame_psnr_db, score
from rigctl.render.warp import Rendered, Renderer, prepare

log = logging.getLogger(__name__)

Box = tuple[int, int, int, int]
MAX_STEPS = 10_000  # views along one --path (a 400 s sequence at 25 fps)
# (col, row) -> (RGB, subject mask) of the truth at that grid position, or None
TruthFn = Callable[[float, float], tuple[F32, NDArray[np.bool_]] | None]


class ViewRow(TypedDict):
    """One written view (``rigctl render --json``: ``views``)."""

    frame: str
    view: str
    col: float
    row: float
    sources: list[str]
    ms: float
    against_truth: NotRequired[Score]


class LeaveOneOutRow(TypedDict):
    """One camera rendered from the others (``rigctl render --leave-one-out --json``)."""

    frame: str
    camera: str
    psnr_db: float
    ssim: float
    ivpsnr_db: float
    pixels: int
    full_frame_psnr_db: float  # premultiplied render against the keyed image, every pixel (score.py)
    sources: list[str]
    ms: float


def renderer_for(frame: FrameViews, taps: int = 4, previous: Renderer | None = None) -> Renderer:
    """A renderer of ``frame``'s cameras that have a disparity; with ``previous`` (the last frame's), its
    sources' images are written over rather than made afresh."""
    old = {s.name: s for s in previous.sources} if previous is not None else {}
    srcs = [
        prepare(v.name, v.offset, v.rgb, v.alpha, v.disparity, into=old.get(v.name))
        for v in frame.views.values()
        if v.disparity is not None
    ]
    if not srcs:
        raise ParameterError(f"frame {frame.number}: no camera has a disparity: nothing to render from")
    return Renderer(srcs, taps=taps)


@dataclass(frozen=True)
class Eye:
    """One rendered image: its grid position and file stem."""

    col: float
    row: float
    stem: str


def position_name(col: float, row: float) -> str:
    return f"c{col:g}r{row:g}"


def eyes_for(frame: FrameViews, col: float, row: float, ipd_m: float | None, stem: str | None = None) -> list[Eye]:
    """The image(s) for a position: one, or an eye pair ``ipd_m`` apart along the rows (converted through the
    rig's horizontal spacing), centred on it."""
    stem = stem or position_name(col, row)
    if ipd_m is None:
        return [Eye(col, row, stem)]
    half = ipd_m / frame.spacing / 2
    eyes = [Eye(col - half, row, stem + "_L"), Eye(col + half, row, stem + "_R")]
    for eye in eyes:
        try:
            frame.position(eye.col, eye.row)
        except ParameterError as exc:
            raise ParameterError(
                f"--stereo {ipd_m:g} m puts the eyes {2 * half:g} camera spacings apart ({frame.spacing:g} m "
                f"each): {exc}"
            ) from None
    return eyes


def path_positions(points: list[tuple[float, float]], steps: int) -> list[tuple[float, float]]:
    """``steps`` positions evenly spaced (by length) along the polyline through ``points``."""
    if steps < 2 or len(points) < 2:
        raise ParameterError("--path needs at least two positions and --steps of at least 2")
    if steps > MAX_STEPS:
        raise ParameterError(f"--steps {steps}: at most {MAX_STEPS} views along a path")
    pts = np.array(points, float)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    if seg.sum() == 0:
        raise ParameterError("--path positions are all the same")
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    at = np.linspace(0.0, cum[-1], steps)
    return [(float(np.interp(a, cum, pts[:, 0])), float(np.interp(a, cum, pts[:, 1]))) for a in at]


def write_view(folder: Path, stem: str, rgba: F32, attrs: dict[str, object]) -> None:
    """``stem.png`` (8-bit RGBA, the cameras' BT.709 picture) and ``stem.exr`` (scene-linear Rec. 709 RGB
    premultiplied by ``A`` from the key, with ``chromaticities``: as take export and depth write pictures; half
    floats, PIZ, and whatever ``attrs`` add: the take's time and the view's camera)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{folder}: cannot make the output folder: {exc.strerror}") from None
    png = np.clip(rgba * 255.0 + 0.5, 0, 255).astype(np.uint8)
    publish_png(folder / f"{stem}.png", cv2.cvtColor(png, cv2.COLOR_RGBA2BGRA))
    write_exr(
        folder / f"{stem}.exr",
        picture(rgba[..., :3], rgba[..., 3]),
        {**picture_attributes(None, None), **attrs},
        half=("RGB", "A"),
        compression=OpenEXR.PIZ_COMPRESSION,
    )


# what write_view writes a pixel at most: 8-bit RGBA PNG (4 bytes, deflate never much larger) and half-float RGBA
# EXR (8 bytes, PIZ never much larger), with a margin for what compression adds; and a file's headers
VIEW_BYTES_PER_PIXEL = 13
VIEW_FILE_BYTES = 1 << 16


def views_bytes(views: int, width: int, height: int) -> int:
    """The most ``views`` views of ``width`` x ``height`` written by :func:`write_view` take on disk (PNG + EXR,
    as if neither compressed anything: a render is refused up front rather than the disk filled halfway)."""
    return views * (width * height * VIEW_BYTES_PER_PIXEL + 2 * VIEW_FILE_BYTES)


def render_views(
    inp: RenderInput,
    numbers: list[int],
    eyes: Callable[[FrameViews], list[Eye]],
    out: Path,
    truth: TruthFn | None = None,
    ignore: Box | None = None,
    progress: Callable[[int, int, str], None] | None = None,
) -> list[ViewRow]:
    """Render and write every eye of every frame; score against ``truth`` where the simulator gives one.
    ``progress(views written, views in all, the last one)`` after each view."""
    rows: list[ViewRow] = []
    ren: Renderer | None = None
    total = 0
    for n in numbers:
        frame = inp.frame(n)
        ren = renderer_for(frame, previous=ren)
        wanted = eyes(frame)
        total = total or len(wanted) * len(numbers)  # every frame set has the same eyes
        stems: dict[str, Eye] = {}
        for eye in wanted:  # every position checked before the frame's first view is written
            frame.position(eye.col, eye.row)
            same = stems.setdefault(eye.stem, eye)
            if same is not eye:
                raise ParameterError(
                    f"positions {same.col!r},{same.row!r} and {eye.col!r},{eye.row!r} would both be written as "
                    f"{eye.stem}: give each position once (names keep 6 significant digits)"
                )
        folder = inside(out, out / f"{n:06d}")  # never a link planted to write elsewhere
        earlier = sorted({f.stem for f in folder.glob("*.png")} - set(stems)) if folder.is_dir() else []
        if earlier:
            names = ", ".join(earlier[:4]) + (", ..." if len(earlier) > 4 else "")
            log.warning(
                "%s holds %d view(s) from an earlier run that this one does not write over (%s): a sequence read "
                "from the folder would mix the two", folder, len(earlier), names,
            )  # fmt: skip
        fps, timecode = inp.timing(n)
        for eye, res, ms in _rendered(ren, frame, wanted):
            attrs: dict[str, object] = {
                **picture_attributes(fps, timecode),
                **inp.view_camera(frame, frame.position(eye.col, eye.row)),
                "rigctl:position": f"{eye.col:g},{eye.row:g}",
                "rigctl:sources": ",".join(res.sources),
            }
            if not res.rgba8[..., 3].any():
                log.warning("frame %06d: view %s is empty: no source camera sees anything there", n, eye.stem)
            write_view(folder, eye.stem, res.rgba, attrs)
            row: ViewRow = {
                "frame": f"{n:06d}",
                "view": eye.stem,
                "col": eye.col,
                "row": eye.row,
                "sources": res.sources,
                "ms": round(ms, 2),
            }
            try:  # a comparison with the truth never stops a render
                got = truth(eye.col, eye.row) if truth else None
            except RigctlError as exc:
                log.warning("no comparison with the truth: %s", exc)
                got, truth = None, None
            if got is not None:
                rgb, _subject = got
                alpha = inp.keyer.matte(rgb)
                row["against_truth"] = score(res.rgba[..., :3], rgb, alpha, ignore)
            rows.append(row)
            if progress:
                progress(len(rows), total, f"frame {n:06d} {eye.stem}")
    return rows


def _rendered(ren: Renderer, frame: FrameViews, eyes: list[Eye]) -> Iterator[tuple[Eye, Rendered, float]]:
    """Each eye's view and its milliseconds: the two eyes of a stereo pair (``_L`` then ``_R``) rendered
    together, each on its own thread, as a headset preview would."""
    i = 0
    while i < len(eyes):
        eye = eyes[i]
        pair = eyes[i + 1] if i + 1 < len(eyes) else None
        if pair is not None and eye.stem.endswith("_L") and pair.stem == eye.stem[:-2] + "_R":
            left, right = ren.render_pair(frame.position(eye.col, eye.row), frame.position(pair.col, pair.row))
            for e, res in ((eye, left), (pair, right)):
                yield e, res, res.target_ms + res.shade_ms
            i += 2
            continue
        t0 = time.perf_counter()
        res = ren.render(*frame.position(eye.col, eye.row))
        yield eye, res, (time.perf_counter() - t0) * 1e3
        i += 1


def leave_one_out(
    inp: RenderInput,
    numbers: list[int],
    cameras: list[str] | None = None,
    ignore: Box | None = None,
    progress: Callable[[int, int, str], None] | None = None,
) -> list[LeaveOneOutRow]:
    """Every named camera rendered from the others (never from itself) and scored against its own image;
    ``progress(cameras scored, cameras in all, the last one)`` after each."""
    rows: list[LeaveOneOutRow] = []
    ren: Renderer | None = None
    for n in numbers:
        frame = inp.frame(n)
        names = cameras or sorted(frame.views)
        unknown = [c for c in names if c not in frame.views]
        if unknown:
            raise ParameterError(f"{inp.source}: no camera {', '.join(unknown)} (cameras: {', '.join(frame.views)})")
        ren = renderer_for(frame, previous=ren)
        for cam in names:
            view = frame.views[cam]
            if not [s for s in ren.sources if s.name != cam]:
                raise ParameterError(f"frame {n}: {cam} is the only camera with a disparity: no other to render from")
            if frame.estimated is not None and not frame.estimated - {cam}:
                raise TakeError(
                    f"{inp.disparity_dir}: frame {n}: no camera but {cam} has an estimate in its disparity (every "
                    f"other value is +inf, no estimate): nothing to render {cam} from"
                )
            t0 = time.perf_counter()
            res = ren.render(*view.offset, exclude=(cam,))
            ms = (time.perf_counter() - t0) * 1e3
            alpha = view.alpha if view.keyed else np.ones_like(view.alpha)
            sc = score(res.rgba[..., :3], view.rgb, alpha, ignore)
            full = full_frame_psnr_db(res.rgba, view.rgb, alpha, ignore)
            rows.append(
                {"frame": f"{n:06d}", "camera": cam, "psnr_db": sc["psnr_db"], "ssim": sc["ssim"],
                 "ivpsnr_db": sc["ivpsnr_db"], "pixels": sc["pixels"], "full_frame_psnr_db": full,
                 "sources": res.sources, "ms": round(ms, 2)}
            )  # fmt: skip
            if progress:
                progress(len(rows), len(numbers) * len(names), f"frame {n:06d} {cam}")
    return rows


def format_table(rows: list[LeaveOneOutRow]) -> str:
    lines = [
        f"{'frame':<8} {'camera':<7} {'PSNR dB':>8} {'SSIM':>7} {'IV-PSNR':>8} {'pixels':>8} {'full dB':>8}  sources"
    ]
    for r in rows:
        lines.append(
            f"{r['frame']:<8} {r['camera']:<7} {r['psnr_db']:>8.2f} {r['ssim']:>7.4f} {r['ivpsnr_db']:>8.2f} "
            f"{r['pixels']:>8} {r['full_frame_psnr_db']:>8.2f}  " + " ".join(r["sources"])
        )
    return "\n".join(lines)
