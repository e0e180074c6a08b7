"""``DIR/process.json``: the take's range, how it settled (the state every chunk started from, the rounds), the
chunking, and what happened to every frame set (with the state its chunk started from), rewritten atomically after
each chunk, so a run that is stopped at any moment leaves a ledger a re-run can trust. Typed: a file that is
not a ledger (or one whose entries are not entries) is refused in one line naming it."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, ValidationError

from rigctl.depth.export import FileRecord, is_whole
from rigctl.depth.report import FrameReport
from rigctl.depth.take_range import RangeDecision, SearchRounds, SearchState
from rigctl.errors import TakeError
from rigctl.publish import publish_text
from rigctl.regular import read_regular

log = logging.getLogger(__name__)

LEDGER = "process.json"
MAX_LEDGER_BYTES = 256 << 20  # some 500,000 frame sets with their files' records


class FrameEntry(BaseModel):
    """One frame set: done (with its report and every published file's size and checksum) or failed."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    status: Literal["done", "failed"]
    worker: str = ""
    seconds: float = 0.0
    error: str | None = None
    report: FrameReport | None = None
    files: dict[str, FileRecord] = {}
    start: SearchState | None = None  # the search state its chunk started from (done from another: redone)


class RunSettings(BaseModel):
    """What a run's outputs depend on besides the chunking: the take (its folder and its manifest), the
    calibration it is rectified with, and the depth options. A run on a ledger with other settings is refused
    (its frame sets, and a measured range, would be kept as if they were this run's)."""

    model_config = ConfigDict(extra="forbid")

    take: str  # the take's folder, resolved
    take_sha256: str  # its take.yaml as a model, less the crew's verdict and notes (they change no frame)
    calibration: str | None = None  # resolved, for a take rectified on the workers
    calibration_sha256: str | None = None
    preset: str
    plan: str  # the planned range as given (--near/--far, a disparity range), or "no plan"
    margin_px: float
    cameras: list[str] | None  # sorted; None for every camera
    key: bool
    temporal: bool
    layout: str  # what the exporter writes (process has no option for them: recorded so a new one is seen)
    colour: str

    def differences(self, asked: RunSettings) -> list[str]:
        """Each setting that differs, as "was, asked now" in the words of its option (a file's checksum only
        when the file is the same one: another take's take.yaml differs anyway)."""
        differ = [name for name in type(self).model_fields if getattr(self, name) != getattr(asked, name)]
        for path, checksum in (("take", "take_sha256"), ("calibration", "calibration_sha256")):
            if path in differ and checksum in differ:
                differ.remove(checksum)
        return [f"{_describe(n, getattr(self, n))}, asked {_describe(n, getattr(asked, n))}" for n in differ]


def _describe(name: str, value: Any) -> str:
    if name == "take":
        return f"take {value}"
    if name == "take_sha256":
        return f"the take's take.yaml with sha256 {value[:12]}"
    if name == "calibration":
        return f"--calibration {value}" if value else "no --calibration"
    if name == "calibration_sha256":
        return f"calibration sha256 {value[:12]}" if value else "no calibration"
    if name == "cameras":
        return "--cameras " + " ".join(value) if value else "every camera"
    if name == "key":
        return "keyed" if value else "--no-key"
    if name == "temporal":
        return "temporal" if value else "--no-temporal"
    if name == "margin_px":
        return f"margin {value} px"
    if name == "plan":
        return str(value)
    return f"--{name} {value}"


class LedgerFile(BaseModel):
    model_config = ConfigDict(extra="forbid")

    settings: RunSettings | None = None  # what the frame sets and the range were computed with
    range: RangeDecision | None = None
    search: SearchRounds | None = None  # the state chunks start from now, and how it got there
    reached: SearchState | None = None  # the hull of every chunk's end state under ``search`` (wider: a round)
    chunk: int | None = None  # frame sets per chunk, and warm-up frame sets before each: a run with others
    warmup: int | None = None  # is refused (the outputs depend on them)
    frames: dict[str, FrameEntry] = {}


class Ledger:
    def __init__(self, out: Path) -> None:
        self.path = out / LEDGER
        self.data = LedgerFile()
        if self.path.exists():
            try:
                # a regular file, bounded: a ledger that is /dev/zero or a FIFO is refused, not read for ever
                data = read_regular(self.path, MAX_LEDGER_BYTES, TakeError, "process ledger")
                self.data = LedgerFile.model_validate_json(data)
            except OSError as exc:
                raise TakeError(f"{self.path}: cannot read the process ledger ({exc.strerror})") from None
            except ValidationError as exc:
                err = exc.errors()[0]
                where = ".".join(str(p) for p in err["loc"]) or "the file"
                raise TakeError(
                    f'{self.path}: not a process ledger (expected {{"frames": {{...}}}}): {where}: {err["msg"]}'
                ) from None

    @property
    def frames(self) -> dict[str, FrameEntry]:
        return self.data.frames

    def done(self, name: str) -> bool:
        entry = self.frames.get(name)
        return entry is not None and entry.status == "done"

    def whole(self, name: str, folder: Path) -> bool:
        """Frame ``name`` is done and every file it published is in ``folder`` as written (size, checksum)."""
        entry = self.frames.get(name)
        if entry is None or entry.status != "done" or not entry.files:
            return False
        return all(is_whole(folder / f, rec) for f, rec in entry.files.items())

    def record(self, name: str, entry: FrameEntry) -> None:
        """Note frame ``name``'s outcome (written by the next :meth:`save`)."""
        self.frames[name] = entry

    def save(self) -> None:
        data = self.data.model_dump(mode="json", by_alias=True)
        data["frames"] = dict(sorted(data["frames"].items()))
        # temporary name, fsync, rename, fsync the folder: the ledger a resume trusts survives a power cut
        publish_text(self.path, json.dumps(data, indent=1, default=_finite, allow_nan=False))


def _finite(value: Any) -> Any:
    """JSON never holds NaN or infinity: numpy scalars become floats, non-finite ones null."""
    v = float(value)
    return v if math.isfinite(v) else None
