"""MIV content in: a camera JSON (the common test conditions' ``cameras`` list) and its YUV files, turned into
one grid folder per frame (``grid.yaml``, 16-bit PNG colour, the content's own depth as disparity PFMs in
``truth/``) that ``rigctl depth`` (which scores against it) and ``rigctl render`` read.

Only a planar grid can be a grid: every camera perspective, with one resolution, one square-pixel focal length,
one principal point and one orientation, their centres in one plane facing the way they look, on a lattice of
rows and columns. Anything else is refused in one line naming what breaks it. Cameras are renamed by their
place in the grid, ``r{row}c{col}`` (row 0 at the top, column 0 at the left, seen from behind), and the names
they had are kept in ``import.json``. Axes and depth coding are those of :mod:`rigctl.interop.miv`.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import ParameterError, RigFileError
from rigctl.interop import yuv
from rigctl.interop.miv import levels_disparity, omaf_to_cv
from rigctl.regular import read_regular
from rigctl.take.framesets import check_frames

log = logging.getLogger(__name__)

F64 = NDArray[np.float64]
MAX_JSON = 16 << 20
PLANE_TOLERANCE = 0.02  # of the grid's spacing: out of plane or off the lattice by more is refused


@dataclass(frozen=True)
class MivCamera:
    name: str  # the content's own name
    grid_name: str  # r{row}c{col}
    position_cv: F64  # centre in our axes (x right, y down, z forward) of the common orientation, metres
    depth_range: tuple[float, float]
    colour_bits: int
    depth_bits: int
    depth_chroma: bool


@dataclass(frozen=True)
class MivContent:
    """The cameras of a MIV content, placed on a grid."""

    folder: Path
    cameras: list[MivCamera]
    size: tuple[int, int]
    focal_px: float
    principal_cv: tuple[float, float]
    spacing_x: float
    spacing_y: float

    def texture(self, cam: MivCamera) -> Path:
        return self.folder / f"{cam.name}_texture_{self.size[0]}x{self.size[1]}_yuv420p10le.yuv"

    def depth(self, cam: MivCamera) -> Path:
        fmt = "yuv420p16le" if cam.depth_chroma else "gray16le"
        return self.folder / f"{cam.name}_depth_{self.size[0]}x{self.size[1]}_{fmt}.yuv"

    def frame_count(self) -> int:
        w, h = self.size
        counts = [yuv.frame_count(self.texture(c), w, h, c.colour_bits) for c in self.cameras]
        counts += [yuv.frame_count(self.depth(c), w, h, c.depth_bits, c.depth_chroma) for c in self.cameras]
        return min(counts)

    def colour(self, cam: MivCamera, frame: int) -> tuple[NDArray[np.uint16], NDArray[np.uint16], NDArray[np.uint16]]:
        y, cb, cr = yuv.read_frame(self.texture(cam), self.size[0], self.size[1], cam.colour_bits, frame)
        assert cb is not None and cr is not None
        return y, cb, cr

    def disparity(self, cam: MivCamera, frame: int) -> NDArray[np.float32]:
        """The content's depth of ``cam`` as our disparity (px for the horizontal spacing; +inf: none)."""
        levels = yuv.read_frame(self.depth(cam), self.size[0], self.size[1], cam.depth_bits, frame, cam.depth_chroma)[0]
        top = (1 << cam.depth_bits) - 1
        levels16 = np.rint(levels.astype(np.float64) * (65535.0 / top)).astype(np.uint16)
        return levels_disparity(levels16, self.focal_px, self.spacing_x, *cam.depth_range)


def rotation(yaw: float, pitch: float, roll: float) -> F64:
    """MIV's R = Rz(yaw) Ry(pitch) Rx(roll), degrees."""
    a, b, c = (math.radians(v) for v in (yaw, pitch, roll))
    rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rx = np.array([[1, 0, 0], [0, math.cos(c), -math.sin(c)], [0, math.sin(c), math.cos(c)]])
    return np.asarray(rz @ ry @ rx, np.float64)


def _field(path: Path, cam: dict[str, Any], key: str, n: int | None = None) -> Any:
    name = cam.get("Name", "?")
    if key not in cam:
        raise RigFileError(f"{path}: camera {name}: {key} is missing")
    v = cam[key]
    if n is not None:
        ok = isinstance(v, list) and len(v) == n
        ok = ok and all(isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in v)
        if not ok:
            raise RigFileError(f"{path}: camera {name}: {key} must be {n} finite numbers, got {v!r}")
    return v


MIN_NEAR_M = 1e-3  # as `rigctl plan` and `usd` hold distances: 1 mm to 1,000 km
MAX_POSITION_M = 1e6
MAX_INT_DIGITS = 100  # no field of a camera file needs more; Python itself stops at 4300 and names its own knob


def _whole(path: Path, digits: str) -> int:
    if len(digits.lstrip("-")) > MAX_INT_DIGITS:
        raise RigFileError(
            f"{path}: not a camera file: a whole number of {len(digits.lstrip('-')):,} digits "
            f"(at most {MAX_INT_DIGITS} are read)"
        )
    return int(digits)


def read_content(path: Path) -> MivContent:
    """The camera JSON at ``path`` (its YUV files beside it), checked to be a planar grid."""
    try:  # a regular file of bounded size, checked on the open descriptor (/dev/zero or a FIFO is refused)
        text = read_regular(path, MAX_JSON, RigFileError, "camera file").decode("utf-8")
        doc = json.loads(text, parse_int=lambda digits: _whole(path, digits))
    except OSError as exc:
        raise RigFileError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise RigFileError(f"{path}: not JSON: {exc}") from None
    except RecursionError:  # nested deeper than Python's parser goes: no camera file is
        raise RigFileError(f"{path}: not a camera file: its JSON is nested too deep to read") from None
    cams = doc.get("cameras") if isinstance(doc, dict) else None
    if not isinstance(cams, list) or not cams or not all(isinstance(c, dict) for c in cams):
        raise RigFileError(f'{path}: no "cameras" list')
    first = cams[0]
    size = tuple(int(v) for v in _field(path, first, "Resolution", 2))
    if not all(1 <= v <= 1 << 16 for v in size) or list(size) != first["Resolution"]:
        raise RigFileError(f"{path}: Resolution {first['Resolution']}: must be two whole numbers from 1 to 65536")
    focal = _field(path, first, "Focal", 2)
    pp = _field(path, first, "Principle_point", 2)
    rot = _field(path, first, "Rotation", 3)
    if not 0.05 * size[0] <= focal[0] <= 100 * size[0]:  # the sense a calibration is held to
        raise RigFileError(f"{path}: Focal {focal}: must be 0.05 to 100 image widths ({size[0]} px)")
    seen: set[str] = set()
    for c in cams:
        name = c.get("Name")
        if not isinstance(name, str) or not name or "/" in name or "\0" in name:
            raise RigFileError(f"{path}: a camera has no usable Name ({name!r})")
        if name in seen:  # both would read one camera's files: one grid position would show another's view
            raise RigFileError(f"{path}: camera Name {name!r} is used twice")
        seen.add(name)
        if c.get("Projection", "Perspective") != "Perspective":
            raise RigFileError(
                f"{path}: camera {name}: {c.get('Projection')} projection: only perspective views form a grid"
            )
        for key, want in (("Resolution", list(size)), ("Focal", focal), ("Principle_point", pp), ("Rotation", rot)):
            got = _field(path, c, key, len(want))
            if not np.allclose(got, want, rtol=0, atol=1e-6):
                raise RigFileError(
                    f"{path}: camera {name}: {key} {got} differs from {first.get('Name')}'s {want}: not one planar grid"
                )
        if max(abs(v) for v in _field(path, c, "Position", 3)) > MAX_POSITION_M:
            raise RigFileError(f"{path}: camera {name}: Position {c['Position']} lies beyond {MAX_POSITION_M:g} m")
        near, far = _field(path, c, "Depth_range", 2)
        if not MIN_NEAR_M <= near < far:  # nearer, the disparity overflows (1e-300 m came out infinite)
            raise RigFileError(
                f"{path}: camera {name}: Depth_range {[near, far]} must have {MIN_NEAR_M * 1e3:g} mm <= near < far"
            )
        for key, default, top in (("BitDepthColor", 10, 14), ("BitDepthDepth", 16, 16)):
            bits = c.get(key, default)
            if isinstance(bits, bool) or not isinstance(bits, int) or not 8 <= bits <= top:
                raise RigFileError(f"{path}: camera {name}: {key} {bits!r} must be a whole number from 8 to {top}")
    if abs(focal[0] - focal[1]) > 1e-6 * focal[0] or focal[0] <= 0:
        raise RigFileError(f"{path}: Focal {focal}: the grid needs one positive focal length (square pixels)")
    R = rotation(*rot)
    world = np.array([c["Position"] for c in cams], np.float64)
    local = omaf_to_cv((world - world.mean(axis=0)) @ R)  # R^T p for each row, then our axes
    return _grid(path, cams, local, size, float(focal[0]), pp)  # type: ignore[arg-type]


def _levels(values: F64, what: str, path: Path, names: list[str]) -> tuple[NDArray[np.int64], float]:
    """Lattice indices of 1-D positions and the spacing (0 for one level); refuses what is off the lattice."""
    order = np.sort(values)
    gaps = np.diff(order)
    big = gaps[gaps > 0.25 * max(gaps.max(initial=0.0), 1e-9)]
    if big.size == 0:
        return np.zeros(values.size, np.int64), 0.0
    step = float(big.min())
    idx = np.rint((values - order[0]) / step).astype(np.int64)
    off = np.abs(values - order[0] - idx * step)
    bad = int(np.argmax(off))
    if off[bad] > PLANE_TOLERANCE * step:
        raise RigFileError(
            f"{path}: camera {names[bad]} is {off[bad] * 1e3:.1f} mm off the grid's {what} lattice "
            f"(spacing {step * 1e3:.1f} mm): not a grid"
        )
    return idx, step


def _grid(
    path: Path, cams: list[dict[str, Any]], local: F64, size: tuple[int, int], focal: float, pp: list[float]
) -> MivContent:
    names = [c["Name"] for c in cams]
    cols, sx = _levels(local[:, 0], "column", path, names)
    rows, sy = _levels(local[:, 1], "row", path, names)
    scale = max(sx, sy)
    if scale == 0:
        raise RigFileError(f"{path}: every camera is at one place: not a grid")
    # the spacings as rectification defines them: a lattice o + col a + row b fitted to the centres, |a|, |b|
    design = np.column_stack([np.ones(len(names))] + [v.astype(np.float64) for v, st in ((cols, sx), (rows, sy)) if st])
    coef, *_ = np.linalg.lstsq(design, local, rcond=None)
    sx = float(np.linalg.norm(coef[1])) if sx else 0.0
    sy = float(np.linalg.norm(coef[-1])) if sy else 0.0
    depth = local[:, 2] - np.median(local[:, 2])
    bad = int(np.argmax(np.abs(depth)))
    if abs(depth[bad]) > PLANE_TOLERANCE * scale:
        raise RigFileError(
            f"{path}: camera {names[bad]} is {depth[bad] * 1e3:.1f} mm in front of or behind the plane of the "
            "others: the cameras are not planar"
        )
    seen: dict[tuple[int, int], str] = {}
    out = []
    for i, c in enumerate(cams):
        key = (int(rows[i]), int(cols[i]))
        if key in seen:
            raise RigFileError(f"{path}: cameras {seen[key]} and {names[i]} are at one grid position")
        seen[key] = names[i]
        chroma = c.get("DepthColorSpace", "YUV420") != "YUV400"
        out.append(
            MivCamera(
                names[i],
                f"r{key[0]}c{key[1]}",
                local[i],
                (float(c["Depth_range"][0]), float(c["Depth_range"][1])),
                int(c.get("BitDepthColor", 10)),
                int(c.get("BitDepthDepth", 16)),
                chroma,
            )
        )
    return MivContent(path.parent, out, size, focal, (float(pp[0]) - 0.5, float(pp[1]) - 0.5), sx or sy, sy or sx)


def import_miv(cameras_json: Path, out: Path, frames: range | None = None) -> list[Path]:
    """Grid folders ``out/<frame:06d>/`` (grid.yaml, r{row}c{col}.png at 16 bits, truth/r{row}c{col}.pfm: the
    content's own depth as disparity, which ``rigctl depth`` scores against and ``rigctl render`` can render
    with) for ``frames`` (default: all); returns the folders."""
    from rigctl.pfm import write_pfm
    from rigctl.publish import publish_json, publish_png, publishing_folder, utf8_path

    utf8_path(out)
    if out.exists() or out.is_symlink():
        raise ParameterError(f"{out}: already exists; the import goes into a new folder")
    content = read_content(cameras_json)
    count = content.frame_count()
    numbers = check_frames(frames, range(count), cameras_json, "frame")
    # built under a hidden partial name beside ``out`` and renamed once whole, every file published whole: a
    # killed import leaves no half grid under ``out``, and the same command run again starts over
    with publishing_folder(out, "miv import", "already exists; the import goes into a new folder") as partial:
        for n in numbers:
            folder = partial / f"{n:06d}"
            grid = {"spacing_x": content.spacing_x, "spacing_y": content.spacing_y, "focal_px": content.focal_px}
            publish_json(folder / "grid.yaml", grid)  # JSON is YAML
            for cam in content.cameras:
                y, cb, cr = content.colour(cam, n)
                rgb = yuv.ycbcr_to_rgb(upsample(y, cb, cr), cam.colour_bits)
                png = np.rint(rgb[..., ::-1] * 65535.0).astype(np.uint16)
                publish_png(folder / f"{cam.grid_name}.png", png)
                write_pfm(folder / "truth" / f"{cam.grid_name}.pfm", content.disparity(cam, n))
        names = {c.grid_name: c.name for c in content.cameras}
        publish_json(partial / "import.json", {"source": str(cameras_json), "cameras": names})
    return [out / f"{n:06d}" for n in numbers]


def upsample(y: NDArray[np.uint16], cb: NDArray[np.uint16], cr: NDArray[np.uint16]) -> NDArray[np.uint16]:
    """(3, H, W) from 4:2:0, each chroma sample over its 2x2 block."""
    from rigctl.interop.ivpsnr import upsample_420

    return upsample_420(y, cb, cr)
