"""Common-plane grid rectification of takes: remap tables built once per calibration (and cached on disk by
a hash of it), applied to every frame; the result is a take again, with its rectification recorded.

The geometry is :func:`rigctl.rectgeom.common_plane`, the same definition the simulator's ground truth uses.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from rigctl.calibration_model import ArrayCalibration, load_calibration
from rigctl.errors import CalibrationError, TakeError
from rigctl.interfaces import Frame, FrameFlags
from rigctl.pixfmt import from_rgb
from rigctl.rectgeom import RectifiedGrid, common_plane
from rigctl.take.manifest import TAKE_SPEC, write_manifest
from rigctl.take.reader import TakeReader
from rigctl.take.writer import CameraWriter

RECTIFIED_FORMAT = "BGR3"  # 8-bit colour: no second chroma subsampling after resampling


def calibration_hash(calib: ArrayCalibration) -> str:
    """SHA-256 of the calibration's numbers (not its file's formatting)."""
    data = {n: calib[n].as_dict() for n in calib.names}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


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
            arrays: dict[str, Any] = {f"{n}_xy": m[0] for n, m in maps.items()}
            arrays.update({f"{n}_frac": m[1] for n, m in maps.items()})
            np.savez(tmp, **arrays)
            tmp.replace(path)
        except OSError:
            pass  # no cache (read-only home): tables are rebuilt next time
        return maps

    def frame(self, name: str, image: NDArray[np.uint8], dst: NDArray[np.uint8] | None = None) -> NDArray[np.uint8]:
        m1, m2 = self.maps[name]
        return np.asarray(cv2.remap(image, m1, m2, cv2.INTER_LINEAR, dst=dst, borderMode=cv2.BORDER_CONSTANT))

    def frame_set(self, images: dict[str, NDArray[np.uint8]]) -> dict[str, NDArray[np.uint8]]:
        return {name: self.frame(name, img) for name, img in images.items()}

    def record(self) -> dict[str, Any]:
        """What a rectified take records about its rectification."""
        g = self.grid
        return {
            "calibration_sha256": self.hash,
            "R": g.R.tolist(),
            "K": g.K.tolist(),
            "image_size": list(g.image_size),
            "spacing_x_m": g.spacing_x_m,
            "spacing_y_m": g.spacing_y_m,
            "focal_px": g.focal_px,
            "lattice_residual_mm": g.lattice_residual_m * 1e3,
            "positions_m": {n: g.position_m(n).tolist() for n in self.calibration.names},
        }


def frame_bgr(reader: TakeReader, name: str, i: int) -> NDArray[np.uint8]:
    if reader.pixel_format == "BGR3":
        return reader.frame_bytes(name, i).reshape(reader.height, reader.width, 3)
    rgb = reader.frame_rgb(name, i)
    return np.ascontiguousarray(from_rgb(rgb, "BGR3").reshape(reader.height, reader.width, 3))


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
    return Rectifier(ArrayCalibration(calib.rig, {n: calib[n] for n in reader.names}, calib.reference, calib.meta))


def rectify_take(
    source: Path,
    calibration: Path,
    out: Path,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Rectify every frame of every camera of ``source`` into the new take ``out``."""
    reader = TakeReader(source)
    t_tables = time.perf_counter()
    rect = rectifier_for_take(reader, calibration)
    t_tables = time.perf_counter() - t_tables
    if out.exists():
        raise TakeError(f"{out}: already exists; takes are never overwritten")
    out.mkdir(parents=True)
    w, h = rect.grid.image_size
    total = sum(len(reader.index[n]) for n in reader.names)
    done = 0
    cameras: dict[str, Any] = {}
    t_remap = 0.0
    t_start = time.perf_counter()
    for name in reader.names:
        writer = CameraWriter(name, out, reader.fps, sync_interval_s=0)
        idx = reader.index[name]
        try:
            for i in range(len(idx)):
                rec = idx[i]
                img = frame_bgr(reader, name, i)
                t0 = time.perf_counter()
                res = rect.frame(name, img)
                t_remap += time.perf_counter() - t0
                frame = Frame(
                    name,
                    int(rec["sequence"]),
                    int(rec["capture_ns"]),
                    int(rec["host_ns"]),
                    FrameFlags(int(rec["flags"])) & ~FrameFlags.TIMECODE,
                    memoryview(np.ascontiguousarray(res).reshape(-1).data),
                )
                writer.write(frame, int(rec["set"]))
                done += 1
                if progress:
                    progress(done, total)
        finally:
            writer.close()
        entry = dict(reader.raw["cameras"][name])
        entry.update(essence=writer.essence_path.name, index=writer.index_path.name, frames=writer.frames)
        cameras[name] = entry
    manifest = dict(reader.raw)
    manifest.update(
        spec=TAKE_SPEC,
        take=out.name,
        status="complete",
        format={
            **reader.raw["format"],
            "width": w,
            "height": h,
            "pixel_format": RECTIFIED_FORMAT,
            "bytes_per_frame": w * h * 3,
        },
        cameras=cameras,
        rectification={
            "source_take": str(source.resolve()),
            "calibration": str(calibration.resolve()),
            **rect.record(),
        },
    )
    truth = source / "truth"
    if truth.is_dir():
        shutil.copytree(truth, out / "truth")
        manifest["rectification"]["truth_note"] = (
            "truth/ is copied from the source take; its disparity is exact in the geometry of the true calibration"
        )
    write_manifest(out, manifest)
    elapsed = time.perf_counter() - t_start
    return {
        "take": str(out),
        "frames": total,
        "image_size": [w, h],
        "focal_px": rect.grid.focal_px,
        "tables_s": t_tables,
        "tables_cached": rect.cache_hit,
        "remap_s": t_remap,
        "total_s": elapsed,
    }
