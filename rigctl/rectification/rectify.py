"""Common-plane grid rectification of takes: remap tables built once per calibration (and cached on disk by
a hash of it), applied to every frame; the result is a take again, with its rectification recorded.

The geometry is :func:`rigctl.rectification.geometry.common_plane`, the same definition the simulator's
ground truth uses.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.calibration_model import ArrayCalibration, load_calibration
from rigctl.diskspace import check_free_space
from rigctl.errors import CalibrationError, ParameterError
from rigctl.publish import publishing_folder
from rigctl.rectification.geometry import RectifiedGrid, calibration_hash, common_plane, rectification_record
from rigctl.take.index import RECORD_SIZE
from rigctl.take.manifest import TAKE_SPEC, DamagedFrame, Rectification, write_manifest
from rigctl.take.reader import TakeReader
from rigctl.take.writer import TakeWriter

RECTIFIED_FORMAT = "BGR3"  # 8-bit colour: no second chroma subsampling after resampling


__all__ = ["Rectifier", "RectifyReport", "calibration_hash", "rectify_take"]


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "rigctl" / "remap"


class Rectifier:
    """Remap tables for every camera of a calibration. ``frame_set`` only remaps: no table is built per frame."""

    def __init__(self, calib: ArrayCalibration, cache: Path | None = None) -> None:
        self.calibration = calib
        self.grid: RectifiedGrid = common_plane(calib)
        self.hash = calibration_hash(calib)
        self.cache_hit = False
        self.maps = self._load_or_build(cache if cache is not None else cache_dir())

    def _build(self) -> dict[str, tuple[NDArray[np.int16], NDArray[np.uint16]]]:
        out = {}
        for name in self.calibration.names:
            cam = self.calibration[name]
            m1, m2 = cv2.initUndistortRectifyMap(
                cam.K, cam.dist, self.grid.rectifying_rotation(cam), self.grid.K, self.grid.image_size, cv2.CV_16SC2
            )
            out[name] = (np.asarray(m1, np.int16), np.asarray(m2, np.uint16))
        return out

    def _load_or_build(self, cache: Path) -> dict[str, tuple[NDArray[np.int16], NDArray[np.uint16]]]:
        path = cache / f"{self.hash}.npz"
        if path.exists():
            try:
                with np.load(path) as data:
                    maps = {n: (data[f"{n}_xy"], data[f"{n}_frac"]) for n in self.calibration.names}
                self.cache_hit = True
                return maps
            except (OSError, KeyError, ValueError):
                path.unlink(missing_ok=True)  # a damaged cache entry is rebuilt, never trusted
        maps = self._build()
        try:
            cache.mkdir(parents=True, exist_ok=True)
            tmp = cache / f"{self.hash}.{os.getpid()}.tmp.npz"
            arrays: dict[str, NDArray[np.int16] | NDArray[np.uint16]] = {f"{n}_xy": m[0] for n, m in maps.items()}
            arrays.update({f"{n}_frac": m[1] for n, m in maps.items()})
            save: Callable[..., None] = np.savez  # keyword arrays: numpy's stub types them as its options
            save(tmp, **arrays)
            tmp.replace(path)
        except OSError:
            pass  # no cache (read-only home): tables are rebuilt next time
        return maps

    def frame(self, name: str, image: NDArray[np.uint8], dst: NDArray[np.uint8] | None = None) -> NDArray[np.uint8]:
        m1, m2 = self.maps[name]
        return np.asarray(cv2.remap(image, m1, m2, cv2.INTER_LINEAR, dst=dst, borderMode=cv2.BORDER_CONSTANT))

    def frame_set(self, images: dict[str, NDArray[np.uint8]]) -> dict[str, NDArray[np.uint8]]:
        return {name: self.frame(name, img) for name, img in images.items()}

    def record(self) -> Rectification:
        """What a rectified take records about its rectification (its manifest's rectification section)."""
        return rectification_record(self.calibration, self.grid)


MAX_ZOOM = 2.0  # common focal length over the cameras' mean: beyond, they share under a quarter of their views
MIN_VALID_SHARE = 0.5  # of the rectified image that a camera's pixels cover


def _zoom(calib: ArrayCalibration) -> float:
    mean_f = float(np.mean([(calib[n].K[0, 0] + calib[n].K[1, 1]) / 2 for n in calib.names]))
    return common_plane(calib).focal_px / mean_f


def check_rectification(rect: Rectifier, path: Path) -> None:
    """Refuse a rectification whose common focal length or valid area is degenerate, naming the camera that
    causes it (the one whose absence makes the rest sane)."""
    calib = rect.calibration
    mean_f = float(np.mean([(calib[n].K[0, 0] + calib[n].K[1, 1]) / 2 for n in calib.names]))
    zoom = rect.grid.focal_px / mean_f
    if not (1 / MAX_ZOOM <= zoom <= MAX_ZOOM) and len(calib.names) > 1:

        def without(name: str) -> float:
            rest = {n: calib[n] for n in calib.names if n != name}
            ref = calib.reference if calib.reference in rest else next(iter(rest))
            try:
                return abs(np.log(_zoom(ArrayCalibration(calib.rig, rest, ref, calib.meta))))
            except CalibrationError:
                return np.inf

        culprit = min(calib.names, key=without)
        raise CalibrationError(
            f"{path}: camera {culprit} makes the rectification degenerate: the common focal length would be "
            f"{rect.grid.focal_px:.6g} px, {zoom:.3g} times the cameras' {mean_f:.6g} px (the cameras share too "
            f"little of their views); check its calibration (R, K, dist) or leave it out"
        )
    w, h = calib[calib.names[0]].image_size
    for name in calib.names:
        xy = rect.maps[name][0]
        inside = (xy[..., 0] >= 0) & (xy[..., 0] < w) & (xy[..., 1] >= 0) & (xy[..., 1] < h)
        share = float(np.mean(inside))
        if share < MIN_VALID_SHARE:
            raise CalibrationError(
                f"{path}: camera {name} covers only {share:.0%} of the rectified image (at least "
                f"{MIN_VALID_SHARE:.0%} needed); check its calibration (R, K, dist)"
            )


def frame_bgr(reader: TakeReader, name: str, i: int) -> NDArray[np.uint8]:
    """Frame ``i`` as 8-bit BGR, converted straight from the captured bytes (a damaged frame raises)."""
    return np.asarray(reader.image(name, i, "bgr8"), np.uint8)


def rectifier_for_take(reader: TakeReader, calibration: Path) -> Rectifier:
    """The rectifier of ``calibration`` for the cameras of a take, refused when a camera or the size differs."""
    calib = load_calibration(calibration)
    source = reader.folder
    missing = [n for n in reader.names if n not in calib.cameras]
    if missing:
        raise CalibrationError(f"{calibration}: no calibration for camera(s) {', '.join(missing)} of take {source}")
    sizes = {calib[n].image_size for n in reader.names}
    if sizes != {(reader.width, reader.height)}:
        raise CalibrationError(
            f"{calibration}: calibrated image size {sorted(sizes)} does not match take {source} "
            f"({reader.width}x{reader.height})"
        )
    rect = Rectifier(ArrayCalibration(calib.rig, {n: calib[n] for n in reader.names}, calib.reference, calib.meta))
    check_rectification(rect, calibration)
    return rect


@dataclass
class RectifyReport:
    """What ``rigctl rectify`` did, with the time of each stage (``--json`` prints it)."""

    take: str
    frames: int
    image_size: tuple[int, int]
    focal_px: float
    tables_s: float
    tables_cached: bool
    remap_s: float
    total_s: float
    damaged_skipped: list[DamagedFrame] = field(default_factory=list)

    def to_json(self) -> dict[str, object]:
        return {
            "take": self.take,
            "frames": self.frames,
            "image_size": list(self.image_size),
            "focal_px": self.focal_px,
            "tables_s": self.tables_s,
            "tables_cached": self.tables_cached,
            "remap_s": self.remap_s,
            "total_s": self.total_s,
            "damaged_skipped": [d.model_dump(exclude_none=True) for d in self.damaged_skipped],
        }


def rectify_take(
    source: Path,
    calibration: Path,
    out: Path,
    progress: Callable[[int, int], None] | None = None,
    skip_damaged: bool = False,
) -> RectifyReport:
    """Rectify every frame of every camera of ``source`` into the new take ``out``: each frame read as 8-bit
    BGR, remapped, and appended with its source frame's record (sequence, times, frame set, timecode).

    A damaged source frame stops it (naming file and byte; the CLI removes the partial new take), unless
    ``skip_damaged``: then the frame is left out and listed in the new take's ``damaged_skipped``."""
    truth, real_out = Path(os.path.realpath(source / "truth")), Path(os.path.realpath(out))  # no raise on a loop
    if truth in real_out.parents:  # copied into the new take: into itself
        raise ParameterError(f"--out {out}: lies in the source take's truth/, which the new take copies")
    reader = TakeReader(source, skip_damaged=skip_damaged)
    if reader.manifest.rectification is not None:  # a second warp would only resample it: nothing to gain
        raise ParameterError(
            f"{source}: already rectified (its take.yaml has a rectification section: a rectified take, or an "
            "ideal simulated one, recorded in the common plane); rigctl depth reads it as it is"
        )
    t_tables = time.perf_counter()
    rect = rectifier_for_take(reader, calibration)
    t_tables = time.perf_counter() - t_tables
    w, h = rect.grid.image_size
    frames = sum(len(reader.index[n]) for n in reader.names)
    need = rectified_bytes(frames, w, h, len(reader.names)) + tree_bytes(source / "truth")
    check_free_space(out, need, f"{frames} rectified frames of {w}x{h} (8-bit BGR) and the truth")
    with publishing_folder(out, "rectify", "already exists; takes are never overwritten") as folder:
        return _rectify_into(folder, out, source, calibration, reader, rect, t_tables, progress)


# a camera's files besides its frames and index records (the manifest, sidecars) at most
CAMERA_FILE_BYTES = 1 << 20


def rectified_bytes(frames: int, width: int, height: int, cameras: int) -> int:
    """What a rectified take of ``frames`` frames of ``width`` x ``height`` takes on disk at most: each frame as
    8-bit BGR and its index record, and each camera's other files (the truth is counted apart)."""
    return frames * (width * height * 3 + RECORD_SIZE) + cameras * CAMERA_FILE_BYTES


def tree_bytes(folder: Path) -> int:
    """The bytes of the files under ``folder`` (0 when there is none): what copying it writes."""
    total = 0
    for root, _dirs, names in os.walk(folder):
        for name in names:
            try:
                total += os.stat(os.path.join(root, name)).st_size
            except OSError:
                continue  # a dangling link: the copy says so in its own line
    return total


def _rectify_into(
    folder: Path,
    out: Path,
    source: Path,
    calibration: Path,
    reader: TakeReader,
    rect: Rectifier,
    t_tables: float,
    progress: Callable[[int, int], None] | None,
) -> RectifyReport:
    """The body of :func:`rectify_take`: the new take written into ``folder``, published later as ``out``."""
    w, h = rect.grid.image_size
    total = sum(len(reader.index[n]) for n in reader.names)
    done = 0
    t_remap = 0.0
    t_start = time.perf_counter()
    remapped = np.empty((h, w, 3), np.uint8)  # one output buffer, reused for every frame
    with reader, TakeWriter(folder, reader.fps) as writer:
        for name in reader.names:
            writer.open(name)  # a camera whose every frame is damaged still has its (empty) files
            for i in range(len(reader.index[name])):
                img = reader.image_or_none(name, i, "bgr8")
                if img is None:
                    continue  # damaged and skipped: listed in reader.damaged, never given a fresh checksum
                t0 = time.perf_counter()
                remapped = rect.frame(name, np.asarray(img, np.uint8), remapped)
                t_remap += time.perf_counter() - t0
                writer.append(name, remapped, reader.record(name, i))  # keeps the source's timecode
                done += 1
                if progress:
                    progress(done, total)
    src = reader.manifest
    cameras = {}
    for name in reader.names:
        files = {"essence": f"{name}.essence", "index": f"{name}.index", "frames": writer.writers[name].frames}
        cameras[name] = src.cameras[name].model_copy(update=files)
    record = rect.record().model_copy(
        update={"source_take": str(source.resolve()), "calibration": str(calibration.resolve())}
    )
    truth = source / "truth"
    if truth.is_dir():
        shutil.copytree(truth, folder / "truth")
        record.truth_note = (
            "truth/ is copied from the source take; its disparity is exact in the geometry of the true calibration"
        )
    fmt = src.format.model_copy(
        update={"width": w, "height": h, "pixel_format": RECTIFIED_FORMAT, "bytes_per_frame": w * h * 3}
    )
    manifest = src.model_copy(
        update={
            "spec": TAKE_SPEC,
            "take": out.name,
            "status": "complete",
            "format": fmt,
            "cameras": cameras,
            "rectification": record,
            "damaged_skipped": list(reader.damaged) or src.damaged_skipped,
        }
    )
    write_manifest(folder, manifest)
    return RectifyReport(
        str(out),
        done,
        (w, h),
        rect.grid.focal_px,
        t_tables,
        rect.cache_hit,
        t_remap,
        time.perf_counter() - t_start,
        list(reader.damaged),
    )
