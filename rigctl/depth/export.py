"""A frame set's outputs per camera: disparity + depth as EXR (NUKE layers: the picture in half floats, depth,
disparity and confidence in float32, the take's time and the rectified camera as ``worldToCamera`` /
``worldToNDC``, ``rigctl.exrcam``) and, when asked, PFM and a colour-mapped PNG preview (red near, blue far),
written in a ``rigctl.layout`` layout, or (``atomic``, the farm) staged beside the frame's folder and renamed
into it file by file, each file's size and SHA-256 recorded so a resumed run can tell a whole file from a
damaged one."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import shutil
import uuid
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numba import njit, prange
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict

from rigctl.depth.estimate import DepthResult
from rigctl.depth.grid import Grid
from rigctl.diskspace import check_free_space
from rigctl.disparity_layers import header as disparity_header
from rigctl.disparity_layers import layer_scales, layers, steps
from rigctl.errors import ParameterError
from rigctl.exr import FAST_LOSSLESS, half_picture, picture_attributes, write_exr
from rigctl.exrcam import camera_attributes
from rigctl.keying import Keyer, SoftKey
from rigctl.layout import inside, output_path
from rigctl.pfm import write_pfm
from rigctl.publish import fsync_path, move_into, output_error, publish_png
from rigctl.timecode import Timecode

F32 = NDArray[np.float32]
F16 = NDArray[np.float16]
FORMATS = ("exr", "pfm", "png")  # what a run can write
# what it writes unless asked (issue 24: the PFM and the preview, 9 % of the write, only when asked; the EXR
# holds the disparity the PFM did, rigctl render and rigctl miv read it from there)
DEFAULT_FORMATS = ("exr",)
PARTIAL_PREFIX = ".partial-"
# what one camera's outputs take a pixel at most, as if nothing compressed (with a margin for what compression
# adds): the EXR's half-float RGBA (8 bytes) and float32 depth.Z, confidence and six disparity layers (32); the
# PFM's float32 disparity; the preview's 8-bit RGB (PNG); and each file's headers
OUTPUT_BYTES_PER_PIXEL = {"exr": 44, "pfm": 4, "png": 4}
OUTPUT_FILE_BYTES = 1 << 16


def parse_formats(text: str) -> tuple[str, ...]:
    """``--formats``: a comma-separated choice of :data:`FORMATS` (in their order, each once)."""
    asked = [f.strip().lower() for f in text.split(",") if f.strip()]
    unknown = [f for f in asked if f not in FORMATS]
    if unknown or not asked:
        raise ParameterError(
            f"--formats: expected a comma-separated choice of {', '.join(FORMATS)} (such as exr,pfm), got {text!r}"
        )
    return tuple(f for f in FORMATS if f in asked)


def outputs_bytes(pictures: int, width: int, height: int, formats: tuple[str, ...] = DEFAULT_FORMATS) -> int:
    """The most ``pictures`` cameras' outputs of ``width`` x ``height`` in ``formats`` take on disk: a run is
    refused up front rather than the disk filled halfway (report.json's 1 MB beside them)."""
    per = sum(width * height * OUTPUT_BYTES_PER_PIXEL[f] + OUTPUT_FILE_BYTES for f in formats)
    return pictures * per + (1 << 20)


def check_room(
    out: Path, sets: int, cameras: int, size: tuple[int, int], formats: tuple[str, ...] = DEFAULT_FORMATS
) -> None:
    """Refuse (exit 4, one line) an --out whose file system cannot take ``cameras`` cameras' outputs in ``sets``
    frame sets of ``size`` (``rigctl.diskspace``): before the first of the work, not with the disk full halfway."""
    w, h = size
    what = f"{cameras} cameras' depth in {sets} frame sets at {w}x{h} ({' + '.join(map(str.upper, formats))})"
    check_free_space(out, outputs_bytes(sets * cameras, w, h, formats), what)


def frame_name(number: int) -> str:
    """The folder name of a frame set in the frames layout."""
    return f"{number:06d}"


class FileRecord(BaseModel):
    """A published file as written: its size in bytes and SHA-256."""

    model_config = ConfigDict(extra="forbid")

    size: int
    sha256: str


def file_record(path: Path) -> FileRecord:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return FileRecord(size=path.stat().st_size, sha256=h.hexdigest())


def is_whole(path: Path, record: FileRecord) -> bool:
    """``path`` holds exactly what was recorded (same size, then same checksum)."""
    try:
        if path.stat().st_size != record.size:
            return False
        return file_record(path).sha256 == record.sha256
    except OSError:
        return False


def colour_preview(disparity: F32, d_range: tuple[float, float]) -> NDArray[np.uint8]:
    """Red near, blue far (as in the paper); black where there is no estimate. Compiled, one pass (issue 24:
    the write's share); :func:`colour_preview_reference` is the numpy and OpenCV form it matches bit for bit."""
    lo, hi = d_range
    d = np.ascontiguousarray(disparity, dtype=np.float32)
    out = np.empty((*d.shape, 3), np.uint8)
    if d.size:
        spread = np.float32(hi - lo) if hi > lo else np.float32(0.0)
        ranged = bool(spread > 0)  # a range narrower than float32 can hold maps like no range (all blue)
        _preview(d.reshape(-1), np.float32(lo), spread, ranged, _jet(), out.reshape(-1, 3))
    return out


@functools.cache
def _jet() -> NDArray[np.uint8]:
    """OpenCV's JET colour map as a 256 x 3 BGR table."""
    return np.ascontiguousarray(cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], cv2.COLORMAP_JET)[:, 0])


@njit(parallel=True, cache=True, fastmath=False)
def _preview(
    d: F32, lo: np.float32, spread: np.float32, ranged: bool, jet: NDArray[np.uint8], out: NDArray[np.uint8]
) -> None:
    for p in prange(d.size):
        v = d[p]
        if not np.isfinite(v):
            out[p, 0] = 0
            out[p, 1] = 0
            out[p, 2] = 0
            continue
        i = 0
        if ranged:  # as numpy: (v - lo) / spread in float32, clipped to [0, 1], times 255, truncated
            t = (v - lo) / spread
            t = min(max(t, np.float32(0.0)), np.float32(1.0))
            i = int(t * np.float32(255.0))
        out[p, 0] = jet[i, 0]
        out[p, 1] = jet[i, 1]
        out[p, 2] = jet[i, 2]


def colour_preview_reference(disparity: F32, d_range: tuple[float, float]) -> NDArray[np.uint8]:
    """:func:`colour_preview` in numpy and OpenCV."""
    lo, hi = d_range
    valid = np.isfinite(disparity)
    t = np.zeros(disparity.shape, np.float32)
    if hi > lo:
        t = np.clip((np.where(valid, disparity, lo) - lo) / (hi - lo), 0, 1)
    img = cv2.applyColorMap((t * 255).astype(np.uint8), cv2.COLORMAP_JET)  # high disparity (near) = red
    img[~valid] = 0
    return np.asarray(img)


@dataclass(frozen=True)
class Target:
    """Where one frame's outputs go (``rigctl.layout``) and what the pictures carry: rate and timecode."""

    out: Path
    layout: str
    frame: int
    fps: float | None = None
    timecode: Timecode | None = None
    flat: bool = False  # one picture (a grid folder): DIR/<camera>.<ext>
    colour: str = "rec709"  # rigctl.exr.COLOURS
    durable: bool = True  # False: no file is fsynced here (a staging folder whose writer does it)

    def path(self, camera: str, ext: str) -> Path:
        return output_path(self.out, "flat" if self.flat else self.layout, self.frame, camera, ext)


COMPILED = True  # the depth EXR's 1/Z and disparity layers in one compiled pass; False: numpy's, the reference
KEYER = Keyer()  # the soft key of every EXR picture


def soft_key(image: F32 | None, res: DepthResult, again: Callable[[], F32] | None = None) -> SoftKey:
    """The picture's soft key, from the hard matte depth already computed when it is :data:`KEYER`'s (used
    where the picture lies in [0, 1], where clipping it, as the soft key does first, changes nothing); the same
    key as ``KEYER.soft(image)``, without keying the picture a second time. ``image`` None: made by
    ``again`` (:meth:`Keyer.soft`)."""
    return KEYER.soft(image, res.matte if res.keyed_by == KEYER else None, again=again)


def fresh_soft_key(grid: Grid, name: str, res: DepthResult) -> SoftKey:
    """:func:`soft_key` of camera ``name``'s picture, made by the key and let go of while it is solved (made
    again for the colour): neither the key's callers nor ``grid`` hold it through the solve (issue 24: the
    write's peak, where the next camera's key runs beside this one's EXR)."""
    return soft_key(None, res, again=lambda: grid.frames.fresh(name))


def write_outputs(
    target: Target, name: str, grid: Grid, res: DepthResult, d_range: tuple[float, float], formats: tuple[str, ...]
) -> None:
    """One camera's outputs (:func:`write_all` of it alone)."""
    write_all(target, grid, {name: res}, d_range, formats)


def write_all(
    target: Target,
    grid: Grid,
    results: dict[str, DepthResult],
    d_range: tuple[float, float],
    formats: tuple[str, ...],
    finished: Callable[[Path], None] | None = None,
) -> None:
    """Every camera's outputs, one camera after another. The EXR picture's soft key, the write's dearest part,
    is made in a second thread (numpy and OpenCV let go of the GIL): a camera's while its PFM and PNG are made
    and written and while the camera before it writes its EXR (issue 24: the key and the EXR's compression
    side by side). Each camera's depth layers are made after its key is done, so that the key's temporaries
    and theirs are not held at once (at 3840x2160 that kept the write's peak at 0.98 GiB, not 1.11).
    ``finished``: told of each file once it is at its name (:meth:`Exporter.write` fsyncs and checksums it
    there while the next camera's is made)."""
    cams = list(results)
    with ThreadPoolExecutor(1, thread_name_prefix="soft-key") as beside:

        def start(i: int) -> Future[SoftKey] | None:
            if i >= len(cams) or "exr" not in formats or not results[cams[i]].keyed_a_screen():
                return None
            return beside.submit(fresh_soft_key, grid, cams[i], results[cams[i]])

        pending = start(0)
        for i, name in enumerate(cams):
            res = results[name]
            written = []
            if "pfm" in formats:
                write_pfm(path := target.path(name, ".pfm"), res.disparity, target.durable)
                written.append(path)
            if "png" in formats:
                publish_png(path := target.path(name, ".png"), colour_preview(res.disparity, d_range), target.durable)
                written.append(path)
            key = pending.result() if pending is not None else None
            pending = start(i + 1)
            if "exr" in formats:
                pic = exr_picture(grid, name, res, key, target.colour)
                key = None  # the key's planes go before the depth layers are made and the file encoded
                write_depth_exr(target, name, grid, pic, depth_channels(grid, name, res))
                written.append(target.path(name, ".exr"))
                del pic
            del key
            if finished is not None:
                for path in written:
                    finished(path)


def depth_channels(grid: Grid, name: str, res: DepthResult) -> dict[str, F32]:
    """The EXR's channels but the picture: 1/Z, confidence and the disparity layers. Compiled, in one pass
    over the disparity (``exr_kernels.depth_planes``: the numpy path's bits, which is kept as the reference
    with ``COMPILED`` off, where the disparity is read, made from its packed form, for each)."""
    st = steps(grid.offsets, name)
    if COMPILED:
        from rigctl.exr_kernels import depth_planes  # compiled on first use

        d = np.ascontiguousarray(res.disparity, np.float32)
        scaled = {n: s for n, s in layer_scales(st).items() if s is not None}
        inv_z, planes = np.empty(d.shape, np.float32), np.empty((len(scaled), *d.shape), np.float32)
        scales = np.array(list(scaled.values()), np.float32)
        depth_planes(d, grid.focal_px * grid.spacing, grid.doffs, scales, inv_z, planes)
        made = dict(zip(scaled, planes, strict=True))
        zero = np.zeros(d.shape, np.float32)
        return {"depth.Z": inv_z, "confidence.Y": res.confidence, **{n: made.get(n, zero) for n in layer_scales(st)}}
    z = grid.depth(res.disparity)
    with np.errstate(divide="ignore"):
        inv_z = np.asarray(np.where(np.isfinite(z) & (z > 0), 1.0 / z, np.float32(0.0)), np.float32)
    del z
    return {"depth.Z": inv_z, "confidence.Y": res.confidence, **layers(res.disparity, st)}


def exr_picture(grid: Grid, name: str, res: DepthResult, key: SoftKey | None, colour: str) -> dict[str, F16]:
    """The EXR's picture: scene-linear, A the subject's coverage from the soft ``key`` and RGB its unmixed colour
    premultiplied by it, as NUKE and Unreal read it (unkeyed, no screen or --no-key: opaque). In the half
    floats it is written in, made so at once: the float32 planes are let go of before the file is encoded
    (issue 24: the write's peak, beside the next camera's key; numpy's rounding, as the write's own)."""
    rgb, alpha = (key.foreground, key.alpha) if key is not None else (grid.images[name], res.matte)
    return half_picture(rgb, alpha, colour)


def write_depth_exr(target: Target, name: str, grid: Grid, pic: dict[str, F16], depth: dict[str, F32]) -> None:
    """The camera's EXR: the picture (:func:`exr_picture`) and the ``depth`` channels, with the take's time
    and the rectified camera."""
    channels: dict[str, NDArray[np.floating]] = {**pic, **depth}
    st = steps(grid.offsets, name)
    ox, oy = grid.offsets[name]
    h, w = grid.shape
    attrs = {
        **picture_attributes(target.fps, target.timecode, target.colour),
        **camera_attributes(np.array(grid.centre(name)), grid.focal_px, grid.principal, (w, h)),
        "rigctl:camera": name,
        "rigctl:focal_px": f"{grid.focal_px:.6f}",
        "rigctl:spacing_x": f"{grid.spacing:.6f}",
        "rigctl:offset": f"{ox:.6f} {oy:.6f}",
        "rigctl:disparity": "pixels of the horizontal spacing; depth.Z holds 1/Z",
        **disparity_header(st),
    }
    write_exr(
        target.path(name, ".exr"), channels, attrs, ("RGB", "A"), compression=FAST_LOSSLESS, durable=target.durable
    )


def drop_unasked(target: Target, cameras: list[str], formats: tuple[str, ...]) -> None:
    """Remove the cameras' outputs in the formats this run did not write, left by an earlier run into the same
    folder (one of an older rigctl, which wrote every format, or one asked for more): a camera's outputs are
    then one run's, and no reader takes an earlier run's PFM for this one's disparity (the EXR holds it; a
    script that reads the PFM finds none rather than a stale one). Only files and symlinks are removed; a
    folder or a FIFO at such a name is left as it is (every reader refuses it)."""
    for name in cameras:
        for ext in FORMATS:
            path = target.path(name, f".{ext}")
            if ext in formats or not (path.is_symlink() or path.is_file()):
                continue
            try:
                path.unlink()
            except FileNotFoundError:
                pass
            except OSError as exc:
                raise output_error(path, exc) from None


def durable_record(path: Path) -> FileRecord:
    """Make a written file durable (fsync) and return its record (read back while the page cache has it)."""
    try:
        fsync_path(path)
        return file_record(path)
    except OSError as exc:
        raise output_error(path, exc) from None


def publish(tmp: Path, final: Path, known: dict[str, FileRecord] | None = None) -> dict[str, FileRecord]:
    """Move every finished file into the frame's folder by rename (a reader sees a whole file or none), the
    folder fsynced after (:func:`rigctl.publish.move_into`); returns each file's record (``known``'s where it
    has one: each made durable by :func:`durable_record` as it was written)."""
    known = known or {}
    records = {f.name: known[f.name] if f.name in known else file_record(f) for f in sorted(tmp.iterdir())}
    move_into(tmp, final)
    return records


@dataclass(frozen=True)
class Exporter:
    """Where a run writes a frame set's outputs: ``out`` in ``layout``; ``atomic`` stages them in
    ``out/.partial-<frame>-<id>`` and publishes them into ``out/<frame>`` by rename (frames layout)."""

    out: Path
    layout: str = "frames"
    colour: str = "rec709"
    formats: tuple[str, ...] = DEFAULT_FORMATS
    flat: bool = False
    atomic: bool = False

    def write(
        self,
        number: int,
        grid: Grid,
        results: dict[str, DepthResult],
        d_range: tuple[float, float],
        fps: float | None,
        timecode: Timecode | None,
    ) -> dict[str, FileRecord]:
        target = Target(self.out, self.layout, number, fps, timecode, flat=self.flat, colour=self.colour)
        if not self.atomic:
            write_all(target, grid, results, d_range, self.formats)
            drop_unasked(target, list(results), self.formats)
            return {}
        name = frame_name(number)
        tmp = self.out / f"{PARTIAL_PREFIX}{name}-{uuid.uuid4().hex[:12]}"
        # the files are written unsynced and each made durable and checksummed in a thread while the next
        # camera's is made (issue 24: 0.2 s of a 1920x1080 frame set's write was these fsyncs and reads)
        staging = dataclasses.replace(target, out=tmp, flat=True, durable=False)
        try:
            with ThreadPoolExecutor(1, thread_name_prefix="durable") as finisher:
                done: dict[str, Future[FileRecord]] = {}

                def finished(path: Path) -> None:
                    done[path.name] = finisher.submit(durable_record, path)

                write_all(staging, grid, results, d_range, self.formats, finished)
                known = {n: f.result() for n, f in done.items()}
            records = publish(tmp, inside(self.out, self.out / name), known)
            drop_unasked(target, list(results), self.formats)  # after: the frame's folder is never emptier
            return records
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
