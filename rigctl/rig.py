"""The rig model: what a rig file (``rigs/*.yaml``, ``spec: 1``) says, validated.

Lengths are metres and angles degrees unless a field's name says otherwise (``width_mm``,
``focal_length_mm``). Optional sections (tally, camera control, reference, USB identities, storage,
plan defaults) are ``None`` when a rig does not have them, and nothing that needs them is shown or run.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from rigctl.errors import RigFileError
from rigctl.layout import SAFE_CAMERA, misspelt
from rigctl.yamlfile import check_spec, describe_validation_error, line_of, load_yaml_with_lines

RIG_SPEC = 1
CAMERA_NAME = SAFE_CAMERA  # r{row}c{col}: ASCII digits, no leading zeros (rigctl.layout)
PIXEL_FORMATS = ("UYVY", "YUYV", "BGR3", "GREY", "Y210", "v210")  # Y210, v210: 10-bit 4:2:2 (rigctl.yuv10)

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Millimetres = Annotated[float, Field(gt=0, le=1000, allow_inf_nan=False)]  # a sensor, a lens: under a metre
# A rectilinear lens's focal length in picture widths, from a 170 degree to a 0.6 degree field of view: what a
# calibration, a grid folder and a rectified take are held to (``calibration_model``, ``depth.grid_folder``,
# ``take.manifest``)
FOCAL_RANGE_WIDTHS = (0.05, 100.0)
MAX_FRAME_PIXELS = 1 << 27  # 134 million pixels (16384 x 8192); rigctl.take.proof holds takes to the same
PositiveInt = Annotated[int, Field(gt=0)]


class _Section(BaseModel):
    # strict: ``rows: true`` is not 1, ``width_px: "960"`` is not a number (YAML already gives numbers as numbers)
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class Sensor(_Section):
    """Active sensor area that the output format covers."""

    width_mm: Millimetres
    height_mm: Millimetres


class OutputFormat(_Section):
    """What each camera delivers to the host."""

    width_px: Annotated[int, Field(gt=0, le=65536)]
    height_px: Annotated[int, Field(gt=0, le=65536)]
    fps: Annotated[float, Field(ge=1, le=1000, allow_inf_nan=False)]  # a camera's rate, not a time-lapse's
    pixel_format: Literal["UYVY", "YUYV", "BGR3", "GREY", "Y210", "v210"] = "UYVY"

    @model_validator(mode="after")
    def _pixel_budget(self) -> OutputFormat:
        if self.width_px * self.height_px > MAX_FRAME_PIXELS:
            raise ValueError(
                f"{self.width_px}x{self.height_px} is over the budget of {MAX_FRAME_PIXELS:,} pixels a frame"
            )
        if self.pixel_format in ("Y210", "v210") and self.width_px % 2:
            raise ValueError(f"{self.pixel_format} is 4:2:2 (a chroma sample a pixel pair): width_px must be even")
        return self


class Lens(_Section):
    focal_length_mm: Millimetres


class GridLayout(_Section):
    """A planar rectangular grid, row 0 at the top, column 0 at the left, seen from behind the rig."""

    rows: Annotated[int, Field(ge=1, le=64)]
    columns: Annotated[int, Field(ge=1, le=64)]
    spacing_x_m: Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)]  # cameras of one rig: within 10 m
    spacing_y_m: Annotated[float, Field(gt=0, le=10, allow_inf_nan=False)]


class UsbIdentity(_Section):
    """Which physical USB device a camera or port is: matched by ``rigctl devices`` after every boot."""

    vendor_id: Annotated[int, Field(ge=0, le=0xFFFF)]
    product_id: Annotated[int, Field(ge=0, le=0xFFFF)]
    serial: str | None = None
    bus_path: str | None = None


class CameraAssignment(_Section):
    name: str
    device: str = Field(min_length=1)
    usb: UsbIdentity | None = None

    @field_validator("name")
    @classmethod
    def _grid_name(cls, value: str) -> str:
        if not CAMERA_NAME.match(value) and misspelt(value) is None:  # r01c0: refused naming r1c0 below
            raise ValueError("must be a grid position r{row}c{col}, e.g. r1c1")
        return value


class PlanDefaults(_Section):
    """The shot the rig is planned for; ``rigctl plan`` and depth use it when no values are given."""

    subject_depth_m: PositiveFloat | None = None
    near_m: PositiveFloat | None = None
    far_m: Annotated[float, Field(gt=0)] | None = None  # may be .inf: background at infinity
    budget_fraction: Annotated[float, Field(gt=0, le=1)] = 0.04


# The highest display address each tally protocol can carry: TSL UMD 3.1 sends 0x80 + address in one byte
# (0..126); TSL UMD 5.0 a 16-bit INDEX whose 0xFFFF means every display of the screen (broadcast), which one
# camera's display must not take. ``bmd-embedded`` numbers cameras by ``camera_control.camera_ids``.
TALLY_ADDRESS_MAX = {"tsl-umd-3.1": 126, "tsl-umd-5.0": 0xFFFE, "bmd-embedded": 126}
TSL5_BROADCAST = 0xFFFF


class Tally(_Section):
    protocol: Literal["tsl-umd-3.1", "tsl-umd-5.0", "bmd-embedded"]
    port: str = Field(min_length=1)
    addresses: dict[str, Annotated[int, Field(ge=0)]] | None = None  # upper bound by protocol: TALLY_ADDRESS_MAX
    pad_with_nul: bool = False
    usb: UsbIdentity | None = None  # the USB-serial adapter behind ``port``


class CameraControlSection(_Section):
    """Camera control through an SDI bridge (see the bridge protocol in the README)."""

    bridge: str = Field(min_length=1)
    camera_ids: dict[str, Annotated[int, Field(ge=0, le=254)]] | None = None
    usb: UsbIdentity | None = None  # the bridge's USB-serial link


class Reference(_Section):
    source: Literal["internal", "program", "external"] = "external"


class Storage(_Section):
    path: str = Field(min_length=1)
    cameras: list[str] | None = None


class RigModel(_Section):
    spec: Literal[1]
    name: str = Field(min_length=1)
    description: str = ""
    sensor: Sensor
    format: OutputFormat
    lens: Lens
    grid: GridLayout
    cameras: list[CameraAssignment] = Field(min_length=1)
    plan: PlanDefaults | None = None
    tally: Tally | None = None
    camera_control: CameraControlSection | None = None
    reference: Reference | None = None
    storage: list[Storage] | None = None


@dataclass(frozen=True)
class RigCamera:
    """One camera of the rig with its grid position and nominal position in rig coordinates (metres).

    Rig coordinates: origin at the grid centre, x to the right, y down, z towards the scene.
    """

    name: str
    row: int
    col: int
    device: str
    x_m: float
    y_m: float
    usb: UsbIdentity | None = None


@dataclass(frozen=True)
class Rig:
    """A validated rig with derived quantities the planner and the recorder need."""

    model: RigModel
    source: str

    @property
    def name(self) -> str:
        return self.model.name

    @property
    def width_px(self) -> int:
        return self.model.format.width_px

    @property
    def height_px(self) -> int:
        return self.model.format.height_px

    @property
    def fps(self) -> float:
        return self.model.format.fps

    @property
    def frame_period_s(self) -> float:
        return 1.0 / self.model.format.fps

    @property
    def pixel_pitch_m(self) -> tuple[float, float]:
        """Effective pixel pitch at the output resolution (sensor extent over pixels), x and y."""
        s = self.model.sensor
        f = self.model.format
        return s.width_mm * 1e-3 / f.width_px, s.height_mm * 1e-3 / f.height_px

    @property
    def focal_length_m(self) -> float:
        return self.model.lens.focal_length_mm * 1e-3

    @property
    def c0_px(self) -> float:
        """C0 = f / s_p of equation (1): the focal length in horizontal pixels."""
        return self.focal_length_m / self.pixel_pitch_m[0]

    @property
    def c0_y_px(self) -> float:
        return self.focal_length_m / self.pixel_pitch_m[1]

    @property
    def spacing_m(self) -> tuple[float, float]:
        return self.model.grid.spacing_x_m, self.model.grid.spacing_y_m

    @property
    def cameras(self) -> list[RigCamera]:
        g = self.model.grid
        out = []
        for cam in self.model.cameras:
            m = CAMERA_NAME.match(cam.name)
            assert m is not None
            row, col = int(m.group(1)), int(m.group(2))
            out.append(
                RigCamera(
                    name=cam.name,
                    row=row,
                    col=col,
                    device=cam.device,
                    x_m=(col - (g.columns - 1) / 2) * g.spacing_x_m,
                    y_m=(row - (g.rows - 1) / 2) * g.spacing_y_m,
                    usb=cam.usb,
                )
            )
        return sorted(out, key=lambda c: (c.row, c.col))

    def camera(self, name: str) -> RigCamera:
        for cam in self.cameras:
            if cam.name == name:
                return cam
        known = ", ".join(c.name for c in self.cameras)
        raise RigFileError(f"{self.source}: rig has no camera {name!r} (it has {known})")

    @property
    def camera_names(self) -> list[str]:
        return [c.name for c in self.cameras]

    def fov_deg(self) -> tuple[float, float]:
        s = self.model.sensor
        f = self.model.lens.focal_length_mm
        return (
            math.degrees(2 * math.atan(s.width_mm / (2 * f))),
            math.degrees(2 * math.atan(s.height_mm / (2 * f))),
        )

    def to_dict(self) -> dict[str, Any]:
        """The rig as plain data (for a take's manifest snapshot): it loads back with :func:`rig_from_dict`."""
        return self.model.model_dump(mode="json", exclude_none=True)


BUILTIN_RIGS = ("sim-3x3", "bmd-micro-studio-4k-3x3")
DEFAULT_RIG = "sim-3x3"


def _builtin_text(ref: str) -> str | None:
    """The text of a shipped rig named ``ref`` (``sim-3x3``, ``sim-3x3.yaml`` or ``rigs/sim-3x3.yaml``)."""
    path = Path(ref)
    if path.parent not in (Path("."), Path("rigs")):
        return None
    stem = path.name.removesuffix(".yaml")
    if stem not in BUILTIN_RIGS:
        return None
    return (resources.files("rigctl.rigs") / f"{stem}.yaml").read_text(encoding="utf-8")


def load_rig(ref: str | Path | None = None) -> Rig:
    """Load and validate a rig: a path to a YAML file, or the name of a shipped rig (default ``sim-3x3``).

    A path that exists is read from disk; otherwise a shipped rig of that name (``sim-3x3``,
    ``rigs/sim-3x3.yaml``) is used, so the contract's paths work from any directory.
    Raises :class:`RigFileError` naming file, line and field on any problem.
    """
    ref = DEFAULT_RIG if ref is None else ref
    path = Path(ref)
    text = None
    if not path.exists():
        text = _builtin_text(str(ref))
        if text is None:
            raise RigFileError(f"{ref}: no such rig file (shipped rigs: {', '.join(BUILTIN_RIGS)}; or a path)")
        path = Path("rigs") / f"{path.name.removesuffix('.yaml')}.yaml"
    data, lines = load_yaml_with_lines(path, text)
    return rig_from_dict(data, source=str(path), lines=lines)


def rig_from_dict(data: Any, source: str = "<rig>", lines: dict[Any, int] | None = None) -> Rig:
    lines = lines or {}
    check_spec(Path(source), data, lines, RIG_SPEC, "rig file")
    try:
        model = RigModel.model_validate(data)
    except ValidationError as exc:
        raise RigFileError(describe_validation_error(Path(source), exc, lines, RigModel)) from None
    _check_whole_rig(model, source, lines)
    return Rig(model=model, source=source)


def _check_whole_rig(model: RigModel, source: str, lines: dict[Any, int]) -> None:
    """What no single field can say: cameras inside the grid, once each, the grid no larger than its cameras,
    and the optional sections naming cameras of this rig. Each error names the offending entry's line."""

    def fail(loc: tuple[Any, ...], text: str) -> None:
        raise RigFileError(f"{source}:{line_of(lines, loc)}: {text}")

    g = model.grid
    seen: dict[str, int] = {}
    devices: dict[str, int] = {}
    rows, cols = set(), set()
    for i, cam in enumerate(model.cameras):
        if wrong := misspelt(cam.name):  # r01c0 beside r1c0 was two cameras at one place, as in a grid folder
            fail(("cameras", i, "name"), f"cameras[{i}].name {cam.name} {wrong}")
        m = CAMERA_NAME.match(cam.name)
        assert m is not None  # checked by the field validator
        row, col = int(m.group(1)), int(m.group(2))
        if row >= g.rows or col >= g.columns:
            fail(("cameras", i, "name"), f"cameras[{i}].name {cam.name} lies outside the {g.rows}x{g.columns} grid")
        if cam.name in seen:
            fail(
                ("cameras", i, "name"),
                f"cameras[{i}].name {cam.name} appears twice (first as cameras[{seen[cam.name]}])",
            )
        if cam.device in devices:
            fail(
                ("cameras", i, "device"),
                f"cameras[{i}].device {cam.device} is used by two cameras (cameras[{devices[cam.device]}] too)",
            )
        seen[cam.name], devices[cam.device] = i, i
        rows.add(row)
        cols.add(col)
    for key, n, used in (("rows", g.rows, rows), ("columns", g.columns, cols)):
        if max(used) + 1 != n:
            fail(
                ("grid", key),
                f"grid.{key} is {n} but the cameras use {key} 0-{max(used)}: "
                f"make it {max(used) + 1} or add the cameras",
            )
    for section, field_name, names in (
        ("tally", "addresses", (model.tally.addresses or {}) if model.tally else {}),
        ("camera_control", "camera_ids", (model.camera_control.camera_ids or {}) if model.camera_control else {}),
    ):
        for name in names:
            if name not in seen:
                fail(
                    (section, field_name, name),
                    f"{section}.{field_name} names {name}, which is not a camera of this rig",
                )
        _check_one_each(section, field_name, names, seen, fail)
    if model.tally is not None:
        _check_tally_addresses(model.tally, fail)


def _check_one_each(
    section: str, field_name: str, given: dict[str, int], order: dict[str, int], fail: Callable[..., None]
) -> None:
    """No two cameras with one number, given or by default (1..N in the rig file's order, as ``rigctl.tally``
    and ``rigctl.camera_control`` number them): one display lit for two cameras, or one camera sent another's
    settings. Named at the given entry of the two."""
    first: dict[int, str] = {}
    for name, i in order.items():
        number = given.get(name, i + 1)
        other = first.setdefault(number, name)
        if other != name:
            blamed, beside = (name, other) if name in given else (other, name)
            default = "" if beside in given else " by default (1..N in the order of the cameras)"
            fail(
                (section, field_name, blamed),
                f"{section}.{field_name}.{blamed} is {number}, as is {beside}'s{default}: each camera needs its own",
            )


def _check_tally_addresses(tally: Tally, fail: Callable[[tuple[Any, ...], str], None]) -> None:
    """Each address within what ``tally.protocol`` can carry; TSL UMD 5.0's broadcast index is refused, since a
    display message there would paint every display of the screen with one camera's label and lamps."""
    top = TALLY_ADDRESS_MAX[tally.protocol]
    for name, address in (tally.addresses or {}).items():
        loc = ("tally", "addresses", name)
        if tally.protocol == "tsl-umd-5.0" and address == TSL5_BROADCAST:
            fail(
                loc,
                f"tally.addresses.{name} is {address}, TSL UMD 5.0's broadcast index (every display of the "
                f"screen): give {name} its own display, 0..{top}",
            )
        if address > top:
            fail(loc, f"tally.addresses.{name} must be 0..{top} for {tally.protocol}, got {address}")
