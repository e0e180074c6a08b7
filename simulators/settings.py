"""Settings of the simulated array, given as ``--sim KEY=VALUE`` and recorded with every take.

Keys with a camera in them (``drops.r0c1=[5,6,20]``, ``skew_us.r2c2=3000``,
``signal_loss.r1c1=[1.0,1.5]``) set one camera; ``ideal=true`` turns every realism setting off
(a perfect lattice of identical pinhole cameras, which is already rectified).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from rigctl.errors import ParameterError
from rigctl.layout import camera_name_problem, misspelt
from rigctl.rig import Rig

NonNeg = Annotated[float, Field(ge=0, allow_inf_nan=False)]

SCENES = ("presenter", "charuco")
PER_CAMERA = ("skew_us", "drops", "signal_loss")


class SimSettings(BaseModel):
    """Everything the simulated array can be told. Defaults are a realistic rig on a real stage."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    scene: Literal["presenter", "charuco"] = Field("presenter", description="what the cameras see")
    seed: Annotated[int, Field(ge=0, le=2**32 - 1)] = Field(0, description="same seed, same frames, byte for byte")
    ideal: bool = Field(False, description="perfect lattice, identical pinhole cameras, no noise")
    # the presenter scene
    subject_distance_m: Annotated[float, Field(gt=0.3, le=50, allow_inf_nan=False)] = Field(
        2.0, description="distance of the subject's nearest point (hands); it is about 0.9 m deep"
    )
    screen_gap_m: Annotated[float, Field(gt=0.05, le=20)] = Field(1.0, description="green screen behind subject")
    desk: bool = Field(True, description="a desk in front of the presenter")
    motion: bool = Field(True, description="slight motion of the presenter over time")
    motion_states: Annotated[int, Field(ge=1, le=200)] = Field(
        10, description="distinct poses in one 1.6 s motion cycle (each is rendered once and cached)"
    )
    motion_ramp_s: Annotated[float, Field(ge=0, le=60, allow_inf_nan=False)] = Field(
        3.0,
        description="seconds between one pose of the motion joining in and the next, counted from the first "
        "frame (the simulator renders them meanwhile, so the cameras stream at once); 0: every pose from the "
        "first frame, all rendered before the cameras stream",
    )
    edges: Literal["hard", "soft"] = Field(
        "hard",
        description="soft: hair-like strands on the presenter and every edge pixel's colour and coverage from 4x4 "
        "samples (spread over the exposure time when the presenter moves: motion blur); the truth then holds "
        "each camera's alpha and unmixed foreground colour; hard: one ray per pixel, a binary matte",
    )
    texture: Literal["photo", "flat", "repetitive"] = Field(
        "photo", description="photo: real photographs; flat: uniform colours; repetitive: periodic patterns"
    )
    # the charuco scene
    board_poses: Annotated[int, Field(ge=1, le=2000)] = Field(40, description="distinct board poses")
    board_hold_frames: Annotated[int, Field(ge=1, le=1000)] = Field(1, description="frames each pose is held")
    board_distance_m: tuple[float, float] = Field((1.8, 3.2), description="range of board distances")
    board_tilt_deg: Annotated[float, Field(ge=0, le=80)] = Field(40.0, description="largest board tilt")
    # realism (all zero with ideal=true)
    mount_position_mm: NonNeg = Field(0.2, description="sigma of each camera's position error (machined frame)")
    mount_rotation_deg: NonNeg = Field(0.5, description="sigma of each camera's rotation error")
    focal_spread: NonNeg = Field(0.005, description="relative sigma of focal lengths")
    principal_offset_px: NonNeg = Field(2.0, description="sigma of principal point offsets")
    distortion_k1: float = Field(-0.04, ge=-0.5, le=0.5, description="mean radial distortion k1")
    distortion_spread: NonNeg = Field(0.01, description="sigma of k1 between cameras")
    noise: Annotated[NonNeg, Field(le=255)] = Field(1.0, description="sensor noise sigma, 8-bit grey levels")
    exposure_stops: Annotated[float, Field(ge=-8, le=8, allow_inf_nan=False)] = Field(
        0.0,
        description="light reaching the sensors, in stops (+1 doubles it): above 0, highlights beyond nominal "
        "white reach the codes above it (super-whites, up to 254 in 8 bits and 1019 in 10)",
    )
    exposure_spread: NonNeg = Field(0.03, description="relative sigma of exposure between cameras")
    colour_spread: NonNeg = Field(0.02, description="relative sigma of per-channel gains")
    vignetting: Annotated[NonNeg, Field(le=1)] = Field(0.15, description="relative fall-off at the image corners")
    # timing
    deterministic: bool = Field(
        False,
        description="frames paced by the reader on a simulated clock (a fixed origin, one frame period a "
        "frame): every frame delivered, same bytes and timestamps on any machine, for tests, CI and "
        "benchmarks; false: real time, a reader more than 8 frames behind loses frames at the source",
    )
    fps: Annotated[float, Field(gt=0, le=240)] | None = Field(None, description="frame rate (default: rig's)")
    # timing faults within what a real rig shows (a second), not beyond what a take's clock can hold
    jitter_us: Annotated[NonNeg, Field(le=1e6)] = Field(50.0, description="sigma of capture timestamp jitter")
    skew_us: dict[str, Annotated[float, Field(ge=-1e6, le=1e6, allow_inf_nan=False)]] = Field(
        default_factory=dict, description="fixed per-camera timestamp skew (at most a second either way)"
    )
    stagger_ms: Annotated[NonNeg, Field(le=1000)] = Field(0.0, description="largest start-up stagger between cameras")
    drops: dict[str, list[Annotated[int, Field(ge=0)]]] = Field(
        default_factory=dict, description="sequence numbers a camera drops"
    )
    signal_loss: dict[str, tuple[NonNeg, NonNeg]] = Field(
        default_factory=dict, description="[start, end] seconds after stream start with no signal"
    )
    reference_present: bool = Field(True, description="a reference (genlock) signal reaches the cameras")
    unlocked: list[str] = Field(default_factory=list, description="cameras that fail to lock to the reference")
    exposure_us: Annotated[float, Field(gt=0, le=1e6)] = Field(
        20000.0, description="exposure time (camera control can change it; brightness scales with it)"
    )

    @field_validator("skew_us", "drops", "signal_loss", "unlocked")
    @classmethod
    def _camera_keys(cls, value: dict[str, Any] | list[str]) -> dict[str, Any] | list[str]:
        for key in value:
            if wrong := camera_name_problem(key):  # r01c0: 'name it r1c0', as the rig file says
                raise ValueError(f"{key if misspelt(key) else repr(key)} {wrong}")
        return value

    def effective(self) -> SimSettings:
        """These settings with every realism setting zeroed when ``ideal`` is set."""
        if not self.ideal:
            return self
        zero = {
            k: 0.0
            for k in (
                "mount_position_mm",
                "mount_rotation_deg",
                "focal_spread",
                "principal_offset_px",
                "distortion_k1",
                "distortion_spread",
                "noise",
                "exposure_spread",
                "colour_spread",
                "vignetting",
            )
        }
        return self.model_copy(update=zero)


def _value(text: str) -> Any:
    if "," in text and not text.lstrip().startswith(("[", "{")):
        text = f"[{text}]"
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def parse_sim_args(pairs: list[str], base: dict[str, Any] | None = None, rig: Rig | None = None) -> SimSettings:
    """``["seed=7", "drops.r0c1=[5,6]"]`` -> validated settings; errors name the key. With ``rig``, a setting
    naming a camera the rig does not have is refused too (a fault meant for it would silently not happen)."""
    data: dict[str, Any] = dict(base or {})
    for pair in pairs:
        if "=" not in pair:
            raise ParameterError(f"--sim {pair!r}: expected KEY=VALUE (see rigctl record --help)")
        key, _, raw = pair.partition("=")
        key = key.strip()
        value = _value(raw)
        if "." in key:
            outer, _, inner = key.partition(".")
            if outer not in PER_CAMERA:
                raise ParameterError(f"--sim {key}: {outer} is not a per-camera setting ({', '.join(PER_CAMERA)} are)")
            data.setdefault(outer, {})
            data[outer] = {**data[outer], inner: value}
        else:
            data[key] = value
    try:
        settings = SimSettings.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        if err["type"] == "extra_forbidden":
            raise ParameterError(f"--sim {loc}: unknown setting (rigctl record --help lists them)") from None
        msg = str(err["msg"]).removeprefix("Value error, ")
        raise ParameterError(f"--sim {loc}: {msg}, got {err.get('input')!r}") from None
    if rig is not None:
        check_cameras(settings, rig)
    return settings


def check_cameras(settings: SimSettings, rig: Rig) -> None:
    """Every camera a per-camera setting (or ``unlocked``) names is one of ``rig``'s, else one line naming it."""
    for key in (*PER_CAMERA, "unlocked"):
        for camera in getattr(settings, key):
            if camera not in rig.camera_names:
                loc = f"{key}.{camera}" if key in PER_CAMERA else f"{key}={camera}"
                known = ", ".join(rig.camera_names)
                raise ParameterError(f"--sim {loc}: rig {rig.name} has no camera {camera} (its cameras: {known})")


def describe_settings() -> str:
    """One line per setting with its default and meaning, for ``rigctl record --help``."""
    lines = []
    for name, info in SimSettings.model_fields.items():
        default = info.get_default(call_default_factory=True)
        lines.append(f"  {name}={default!r}: {info.description}")
    return "\n".join(lines)
