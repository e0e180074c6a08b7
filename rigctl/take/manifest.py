"""The take manifest, ``take.yaml`` (``spec: 1``): what a take is and what it claims to hold.

One typed model, :class:`Manifest`, is what the recorder writes and what every reader gets back: capture
(format, timing, cameras, frame sets, how the take ended), rectification (a rectified take, or an ideal
simulated take that is rectified as recorded) and the crew's verdict. :func:`write_manifest` takes only the
model and :func:`read_manifest` returns only the model, so a field is spelled once.

It is written when recording starts (``status: recording``) and replaced atomically when the take ends,
so a take interrupted by a crash still says what it is; its frames are then counted from the indexes.

The YAML is the same as before the model existed: sections written as they always were, optional sections
(``frame_sets``, ``end``, ``rectification``, ``verdict``, ``damaged_skipped``) left out until they are set,
and keys another tool added at the top level kept when rigctl rewrites the file.
"""

from __future__ import annotations

import logging
import math
import os
import re
from pathlib import Path
from typing import Annotated, Literal, cast

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    JsonValue,
    StrictInt,
    ValidationError,
    ValidationInfo,
    field_serializer,
    field_validator,
    model_validator,
)
from pydantic.main import IncEx

from rigctl.errors import TakeError
from rigctl.layout import SAFE_CAMERA, misspelt
from rigctl.publish import kind
from rigctl.rig import FOCAL_RANGE_WIDTHS
from rigctl.timecode import Timecode, TimecodeError, rate_of
from rigctl.yamlfile import Loc, check_spec, describe_validation_error, line_of, load_yaml_with_lines

log = logging.getLogger(__name__)

TAKE_SPEC = 1
MANIFEST = "take.yaml"
STATUSES = ("recording", "complete", "ended", "interrupted")
VERDICTS = ("circled", "no-good")
SequenceNumber = Annotated[StrictInt, Field(ge=0, lt=1 << 64)]  # a frame's, as its index record holds it
SIDECAR_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,99}")  # no path: a file beside take.yaml
ROTATION_TOLERANCE = 1e-6  # rectification.R orthonormal, det +1, to this (float32 from other tools errs ~1e-7)
Verdict = Literal["circled", "no-good"]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid")


class CameraEntry(_Section):
    """One camera's files and what was lost where (sequence numbers)."""

    essence: str
    index: str
    frames: int = 0
    first_sequence: SequenceNumber | None = None
    last_sequence: SequenceNumber | None = None
    source_drops: list[int] = []
    error_frames: list[int] = []
    writer_drops: list[int] = []
    not_written: list[int] = []
    ended_early: str | None = None  # why the camera's stream ended before the take did
    format_changed_at: list[int] | None = None  # sequences flagged as a format change

    @model_validator(mode="after")
    def _sequence_span(self) -> CameraEntry:
        """The first and last frame's sequence numbers: both or neither, in order, with a number for every frame
        between them (a reader holds them to the index too: ``rigctl.take.proof.sequence_problems``)."""
        first, last = self.first_sequence, self.last_sequence
        if first is None or last is None:
            if first is not None or last is not None:
                raise ValueError("first_sequence and last_sequence go together: give both or neither")
            return self
        if first > last:
            raise ValueError(f"first_sequence {first} is after last_sequence {last}")
        if last - first + 1 < self.frames:
            raise ValueError(
                f"first_sequence {first} to last_sequence {last} number {last - first + 1} frames, fewer than the "
                f"{self.frames} of frames"
            )
        return self


class FormatEntry(_Section):
    width: Annotated[int, Field(gt=0, le=65536)]
    height: Annotated[int, Field(gt=0, le=65536)]
    pixel_format: str
    fps: Annotated[float, Field(ge=1, le=1000, allow_inf_nan=False)]
    bytes_per_frame: Annotated[int, Field(gt=0)]


class Timing(_Section):
    """When the take ran, on the capture clock; ``start_timecode`` is the take's time-of-day start, typed
    (read with the rate of ``format.fps``)."""

    clock: str = "CLOCK_MONOTONIC"
    t0_ns: StrictInt | None = None
    t1_ns: StrictInt | None = None
    frame_period_ns: StrictInt | None = None
    start_timecode: Timecode | None = None

    model_config = ConfigDict(extra="forbid", arbitrary_types_allowed=True)

    @field_serializer("start_timecode")
    def _tc_text(self, tc: Timecode | None) -> str | None:
        return None if tc is None else str(tc)


class Skew(_Section):
    p50_us: float = 0.0
    p99_us: float = 0.0
    max_us: float = 0.0
    sets: int = 0


class IncompleteSet(_Section):
    number: int
    missing: list[str]


class FrameSetSummary(_Section):
    """The frame sets the recorder assembled; ``file`` (``sets.csv`` beside the manifest) has a row for each
    (``take check`` holds it to this: ``rigctl.take.check.sets_problem``)."""

    count: Annotated[StrictInt, Field(ge=0)]
    complete: Annotated[StrictInt, Field(ge=0)]
    incomplete: list[IncompleteSet] = []
    skew: Skew = Skew()
    file: str = "sets.csv"

    @field_validator("file")
    @classmethod
    def _beside_the_manifest(cls, value: str) -> str:
        if not SIDECAR_NAME.fullmatch(value):
            raise ValueError(f"{value!r:.60} is not a file name beside take.yaml (letters, digits, '.', '_', '-')")
        return value

    @model_validator(mode="after")
    def _counts(self) -> FrameSetSummary:
        numbers = [s.number for s in self.incomplete]
        if self.complete + len(numbers) != self.count:
            raise ValueError(
                f"count {self.count} is not complete {self.complete} plus the {len(numbers)} incomplete sets listed"
            )
        if len(set(numbers)) != len(numbers) or not all(0 <= n < self.count for n in numbers):
            raise ValueError(f"incomplete: set numbers must be distinct, 0 to count - 1 ({self.count - 1})")
        return self


class End(_Section):
    reason: str
    message: str = ""


class Software(_Section):
    name: str = "rigctl"
    version: str = ""


class Devices(_Section):
    description: str = ""
    settings: dict[str, JsonValue] = {}  # the simulator's settings, as given (empty for real cameras)


class Rectification(_Section):
    """The common-plane geometry a take's frames are in (``rigctl.rectification.geometry``): what depth reads."""

    calibration_sha256: str
    R: list[list[float]]
    K: list[list[float]]
    image_size: list[int]
    # what depth computes Z = focal_px * spacing / d with: finite, positive (spacing_y_m 0 for a single row) and
    # within grid.yaml's bounds, beyond which every depth came out 0 or infinite
    spacing_x_m: Annotated[float, Field(ge=1e-6, le=1e6, allow_inf_nan=False)]
    spacing_y_m: Annotated[float, Field(ge=0, le=1e6, allow_inf_nan=False)]
    focal_px: Annotated[float, Field(gt=0, allow_inf_nan=False)]
    lattice_residual_mm: float
    positions_m: dict[str, list[float]]
    source_take: str | None = None  # rigctl rectify: the take it read
    calibration: str | None = None  # rigctl rectify: the calibration file; an ideal take: "true (simulated)"
    truth_note: str | None = None

    @field_validator("focal_px")
    @classmethod
    def _plausible_focal(cls, value: float, info: ValidationInfo) -> float:
        size = info.data.get("image_size")
        lo, hi = FOCAL_RANGE_WIDTHS[0], 2 * FOCAL_RANGE_WIDTHS[1]  # a calibration's, zoomed at most twice by rectify
        if size and not lo * size[0] <= value <= hi * size[0]:
            raise ValueError(
                f"is not plausible for an image {size[0]} px wide (expected {lo * size[0]:g} to {hi * size[0]:g} px)"
            )
        return value

    @field_validator("positions_m")
    @classmethod
    def _camera_names(cls, value: dict[str, list[float]]) -> dict[str, list[float]]:
        for name, p in value.items():
            if not SAFE_CAMERA.fullmatch(name):
                raise ValueError(f"{name!r} is not a camera name r{{row}}c{{col}}")
            # a camera's centre in metres: NaN made every camera's offset NaN, a short list a traceback
            if len(p) != 3 or not all(math.isfinite(v) and abs(v) <= 1e6 for v in p):
                raise ValueError(f"{name}: expected [x, y, z], three finite numbers within 1e6, got {p!r:.60}")
        return value

    @field_validator("R", "K")
    @classmethod
    def _matrix(cls, value: list[list[float]], info: ValidationInfo) -> list[list[float]]:
        if len(value) != 3 or any(len(row) != 3 or not all(math.isfinite(v) for v in row) for row in value):
            raise ValueError(f"expected 3x3 finite numbers, got {value!r:.60}")
        if info.field_name == "R":
            _rotation(value)
        return value

    @model_validator(mode="after")
    def _camera_matrix(self) -> Rectification:
        """K is a camera: focal lengths as plausible as ``focal_px``, square to within 2:1, the principal point
        inside the image, last row [0, 0, 1] (fx 0 wrote a USD aperture of infinity, exit 0)."""
        (fx, _, cx), (_, fy, cy), last = self.K
        if len(self.image_size) != 2:
            raise ValueError(f"image_size must be [width, height], got {self.image_size!r:.40}")
        w, h = self.image_size
        lo, hi = FOCAL_RANGE_WIDTHS[0] * w, 2 * FOCAL_RANGE_WIDTHS[1] * w
        if not (lo <= fx <= hi and lo <= fy <= hi and 0.5 <= fx / fy <= 2 and -1 <= cx <= w and -1 <= cy <= h):
            raise ValueError(
                f"camera matrix K (fx {fx:g}, fy {fy:g}, cx {cx:g}, cy {cy:g}) is not a camera for {w}x{h} px images"
            )
        if last != [0, 0, 1]:
            raise ValueError(f"camera matrix K must end in the row [0, 0, 1], got {last!r:.40}")
        return self


def _rotation(R: list[list[float]]) -> None:
    """``R`` is a rotation: orthonormal rows and determinant +1, to ``ROTATION_TOLERANCE`` (its entries are at
    most 1, so absolute is relative): a scaled, sheared or mirrored R was taken, and depth and the USD cameras
    built on it came out skewed, exit 0."""
    gram = [[sum(a * b for a, b in zip(R[i], R[j], strict=True)) for j in range(3)] for i in range(3)]
    off = max(abs(gram[i][j] - (i == j)) for i in range(3) for j in range(3))
    (a, b, c), (d, e, f), (g, h, k) = R
    det = a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g)
    if off > ROTATION_TOLERANCE or abs(det - 1) > ROTATION_TOLERANCE:
        raise ValueError(
            f"is not a rotation: R R^T differs from the identity by {off:.3g} and det(R) is {det:.6g} "
            f"(a rotation: 0 and 1, to {ROTATION_TOLERANCE:g})"
        )


class DamagedFrame(_Section):
    """A frame left out because it was damaged (``--skip-damaged``), with where it was found."""

    camera: str
    file: str
    byte: int
    problem: str
    sequence: int | None = None


# sections left out of the YAML while they are unset, as the manifest was written before it had a model
_OPTIONAL = ("software", "checksum", "devices", "frame_sets", "end", "rectification", "verdict", "damaged_skipped")


class Manifest(BaseModel):
    """A take's manifest: capture, rectification and verdict sections. Unknown top-level keys (another tool's)
    are kept as they were written."""

    model_config = ConfigDict(extra="allow", validate_assignment=True)

    spec: int
    take: str
    status: str
    started_utc: str = ""
    software: Software | None = None
    rig: dict[str, JsonValue] = {}  # the rig file as recorded (``rigctl.rig.rig_from_dict`` loads it)
    format: FormatEntry
    timing: Timing = Timing()
    checksum: str | None = None
    devices: Devices | None = None
    cameras: dict[str, CameraEntry]
    notes: list[str] = []
    frame_sets: FrameSetSummary | None = None
    end: End | None = None
    rectification: Rectification | None = None
    verdict: Verdict | None = None
    damaged_skipped: list[DamagedFrame] | None = None

    @field_validator("cameras")
    @classmethod
    def _camera_names(cls, value: dict[str, CameraEntry]) -> dict[str, CameraEntry]:
        """Camera names become file names: only grid positions ``r{row}c{col}``, and at least one camera."""
        if not value:
            raise ValueError("the take has no cameras")
        for name in value:
            if not SAFE_CAMERA.fullmatch(name):
                raise ValueError(f"{name!r} is not a camera name r{{row}}c{{col}}")
        return value

    @field_validator("status")
    @classmethod
    def _known_status(cls, value: str) -> str:
        if value not in STATUSES:
            raise ValueError(f"{value!r} is not a status ({', '.join(STATUSES)})")
        return value

    @field_validator("timing", mode="before")
    @classmethod
    def _typed_timecode(cls, value: object, info: ValidationInfo) -> object:
        """``timing.start_timecode`` as text in the file, a :class:`Timecode` at the rate of ``format.fps``."""
        if not isinstance(value, dict) or not isinstance(value.get("start_timecode"), str):
            return value
        fmt = info.data.get("format")
        if not isinstance(fmt, FormatEntry):
            return {k: v for k, v in value.items() if k != "start_timecode"}  # the format's own error is raised
        text = value["start_timecode"]
        try:
            tc = Timecode.parse(text, rate_of(fmt.fps)[0])
        except TimecodeError as exc:
            raise ValueError(f"start_timecode {text!r}: {exc}") from None
        return {**value, "start_timecode": tc}

    def mark(self, verdict: str, note: str = "") -> None:
        """Set the crew's verdict, and say it (with the note) in the notes."""
        if verdict not in VERDICTS:
            raise TakeError(f"{self.take}: unknown verdict {verdict!r} ({', '.join(VERDICTS)})")
        self.verdict = cast(Verdict, verdict)
        self.notes = [*self.notes, f"{verdict}: {note}" if note else verdict]

    def to_yaml_data(self) -> dict[str, object]:
        """The manifest as the YAML holds it: optional sections and keys left out while unset."""
        exclude: dict[str, IncEx | bool] = {k: True for k in _OPTIONAL if getattr(self, k) is None}
        cams = {
            n: {k for k in ("ended_early", "format_changed_at") if getattr(e, k) is None}
            for n, e in self.cameras.items()
        }
        exclude["cameras"] = {n: keys for n, keys in cams.items() if keys}
        if self.rectification is not None:
            r = self.rectification
            exclude["rectification"] = {
                k for k in ("source_take", "calibration", "truth_note") if getattr(r, k) is None
            }
        return dict(self.model_dump(mode="json", exclude=exclude))


def write_manifest(folder: Path, manifest: Manifest) -> None:
    """Replace ``folder/take.yaml`` atomically (write, fsync, rename, fsync the folder)."""
    path = folder / MANIFEST
    tmp = folder / (MANIFEST + ".tmp")
    text = yaml.safe_dump(manifest.to_yaml_data(), sort_keys=False, default_flow_style=None, width=120)
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    dir_fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def read_manifest(folder: Path) -> Manifest:
    """The validated manifest; errors name file, line and field."""
    path = folder / MANIFEST
    if not folder.is_dir():
        if folder.exists():  # /dev/null, a file: it is there, it is just no folder
            raise TakeError(f"{folder}: exists but is {kind(folder.stat().st_mode)}, not a take folder")
        raise TakeError(f"{folder}: no such take folder")
    if not path.exists():
        raise TakeError(f"{path}: missing: {folder} is not a take (no manifest)")
    data, lines = load_yaml_with_lines(path)
    check_spec(path, data, lines, TAKE_SPEC, "take manifest")
    _refuse_misspelt_cameras(path, data, lines)
    try:
        return Manifest.model_validate(data)
    except ValidationError as exc:
        raise TakeError(describe_validation_error(path, exc, lines)) from None


def _refuse_misspelt_cameras(path: Path, data: dict[str, object], lines: dict[Loc, int]) -> None:
    """A camera named as its grid position is not written (``r01c0``, ``r٢c1``) is refused on its line, naming
    the name to use, as in a rig file and a grid folder: one camera named two ways was two cameras at one place.
    (A name that is no grid position at all is refused by the model's validators.)"""
    for loc in (("cameras",), ("rectification", "positions_m")):
        section: object = data
        for key in loc:
            section = section.get(key) if isinstance(section, dict) else None
        for name in section if isinstance(section, dict) else ():
            if wrong := misspelt(name):
                field = ".".join(loc)
                raise TakeError(f"{path}:{line_of(lines, (*loc, name))}: {field}: camera name {name} {wrong}")
    rig = data.get("rig")
    cams = rig.get("cameras") if isinstance(rig, dict) else None
    for i, cam in enumerate(cams if isinstance(cams, list) else ()):
        if isinstance(cam, dict) and (wrong := misspelt(cam.get("name"))):
            where = line_of(lines, ("rig", "cameras", i, "name"))
            raise TakeError(f"{path}:{where}: rig.cameras[{i}].name: camera name {cam['name']} {wrong}")
