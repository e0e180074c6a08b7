"""The take manifest, ``take.yaml`` (``spec: 1``): what a take is and what it claims to hold.

It is written when recording starts (``status: recording``) and replaced atomically when the take ends,
so a take interrupted by a crash still says what it is; its frames are then counted from the indexes.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from rigctl.errors import TakeError
from rigctl.yamlfile import check_spec, describe_validation_error, load_yaml_with_lines

TAKE_SPEC = 1
MANIFEST = "take.yaml"
STATUSES = ("recording", "complete", "ended", "interrupted")


class CameraEntry(BaseModel):
    model_config = ConfigDict(extra="allow")

    essence: str
    index: str
    frames: int = 0
    first_sequence: int | None = None
    last_sequence: int | None = None
    source_drops: list[int] = []
    error_frames: list[int] = []
    writer_drops: list[int] = []
    not_written: list[int] = []


class FormatEntry(BaseModel):
    model_config = ConfigDict(extra="allow")

    width: Annotated[int, Field(gt=0, le=65536)]
    height: Annotated[int, Field(gt=0, le=65536)]
    pixel_format: str
    fps: Annotated[float, Field(gt=0, le=1000, allow_inf_nan=False)]
    bytes_per_frame: Annotated[int, Field(gt=0)]


class Manifest(BaseModel):
    """The parts of a manifest every reader relies on; anything else is kept as it was written."""

    model_config = ConfigDict(extra="allow")

    spec: int
    take: str
    status: str
    format: FormatEntry
    cameras: dict[str, CameraEntry]
    timing: dict[str, Any] = {}
    frame_sets: dict[str, Any] = {}
    rig: dict[str, Any] = {}
    notes: list[str] = []


def write_manifest(folder: Path, data: dict[str, Any]) -> None:
    """Replace ``folder/take.yaml`` atomically (write, fsync, rename, fsync the folder)."""
    path = folder / MANIFEST
    tmp = folder / (MANIFEST + ".tmp")
    text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=120)
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


def read_manifest(folder: Path) -> tuple[Manifest, dict[str, Any]]:
    """The validated manifest and the raw data; errors name file, line and field."""
    path = folder / MANIFEST
    if not folder.is_dir():
        raise TakeError(f"{folder}: no such take folder")
    if not path.exists():
        raise TakeError(f"{path}: missing: {folder} is not a take (no manifest)")
    data, lines = load_yaml_with_lines(path)
    check_spec(path, data, lines, TAKE_SPEC, "take manifest")
    try:
        return Manifest.model_validate(data), data
    except ValidationError as exc:
        raise TakeError(describe_validation_error(path, exc, lines)) from None
