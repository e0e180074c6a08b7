"""Reading a take: manifest, per-camera indexes, frames (never a partial one) and frame sets."""

from __future__ import annotations

import os
import zlib
from functools import cached_property
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import TakeError
from rigctl.interfaces import FrameFlags
from rigctl.pixfmt import to_rgb
from rigctl.take import framesets
from rigctl.take.index import IndexProblem, read_index
from rigctl.take.manifest import Manifest, read_manifest
from rigctl.timecode import Timecode, TimecodeError, rate_of, start_timecode


class TakeReader:
    """A take folder opened for reading. Frames are addressed by camera and position in its index."""

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self.manifest, self.raw = read_manifest(self.folder)
        self.names = list(self.manifest.cameras)
        fmt = self.manifest.format
        self.width, self.height, self.pixel_format, self.fps = fmt.width, fmt.height, fmt.pixel_format, fmt.fps
        self.bytes_per_frame = fmt.bytes_per_frame
        self.period_ns = int(self.manifest.timing.get("frame_period_ns") or round(1e9 / fmt.fps))
        self.index: dict[str, NDArray[np.void]] = {}
        self.problems: dict[str, list[IndexProblem]] = {}
        for name in self.names:
            essence = self.essence_path(name)
            if not essence.exists():
                raise TakeError(f"{essence}: essence file of camera {name} is missing")
            idx, problems = read_index(self.index_path(name), essence.stat().st_size)
            self.index[name] = idx
            self.problems[name] = problems

    @property
    def status(self) -> str:
        return self.manifest.status

    def _resolve(self, text: str) -> Path:
        p = Path(text)
        return p if p.is_absolute() else self.folder / p

    def essence_path(self, name: str) -> Path:
        return self._resolve(self.manifest.cameras[name].essence)

    def index_path(self, name: str) -> Path:
        path = self._resolve(self.manifest.cameras[name].index)
        if not path.exists():
            raise TakeError(f"{path}: index file of camera {name} is missing")
        return path

    def frame_bytes(self, name: str, i: int, verify: bool = False) -> NDArray[np.uint8]:
        """The bytes of frame ``i`` of camera ``name``, exactly as captured."""
        rec = self.index[name][i]
        size, offset = int(rec["size"]), int(rec["offset"])
        path = self.essence_path(name)
        fd = os.open(path, os.O_RDONLY)
        try:
            data = os.pread(fd, size, offset)
        finally:
            os.close(fd)
        if len(data) != size:
            raise TakeError(f"{path}: byte {offset}: frame of {size} bytes is cut short ({len(data)} read)")
        if verify and rec["crc"] and zlib.crc32(data) != int(rec["crc"]):
            raise TakeError(f"{path}: byte {offset}: frame {int(rec['sequence'])} fails its checksum")
        return np.frombuffer(data, dtype=np.uint8)

    def frame_rgb(self, name: str, i: int) -> NDArray[np.float32]:
        """Frame ``i`` of ``name`` as RGB float32 in [0, 1] (converted from the captured pixel format)."""
        return to_rgb(self.frame_bytes(name, i), self.pixel_format, self.width, self.height)

    @cached_property
    def frame_sets(self) -> list[framesets.FrameSet]:
        """Frame sets assembled from the indexes (the same rule the recorder used)."""
        stamps = {n: self.index[n]["capture_ns"].astype(np.int64) for n in self.names}
        try:
            timecodes = framesets.timecode_counts(self.index, self.fps)
        except TimecodeError as exc:
            raise TakeError(f"{self.folder}: {exc}") from None
        t0 = self.manifest.timing.get("t0_ns")
        return framesets.assemble(stamps, self.period_ns, t0, timecodes)

    def timecode_rate(self, drop: bool) -> tuple[int, bool]:
        """The nominal rate of the take's timecode counts (from its fps), and the drop flag as recorded."""
        try:
            rate, _ = rate_of(self.fps)
            Timecode(0, rate, drop)
        except TimecodeError as exc:
            raise TakeError(f"{self.folder}: format.fps {self.fps:g}: {exc}") from None
        return rate, drop

    def timecode(self, name: str, i: int) -> Timecode | None:
        """The timecode frame ``i`` of ``name`` carried from its source, or None."""
        rec = self.index[name][i]
        flags = FrameFlags(int(rec["flags"]))
        if not flags & FrameFlags.TIMECODE:
            return None
        rate, drop = self.timecode_rate(bool(flags & FrameFlags.DROP_FRAME))
        try:
            return Timecode(int(rec["timecode"]), rate, drop)
        except TimecodeError as exc:
            path = self.index_path(name)
            raise TakeError(f"{path}: record {i}: {exc}") from None

    def set_timecode(self, fs: framesets.FrameSet) -> Timecode:
        """The timecode of a frame set: its members' own, else the take's time-of-day start plus the set number
        (the same rule as the ALE and the shoot UI)."""
        for name, i in fs.members.items():
            tc = self.timecode(name, i)
            if tc is not None:
                return tc
        return start_timecode(str(self.raw.get("started_utc", "")), self.fps) + fs.number

    def complete_sets(self) -> list[framesets.FrameSet]:
        return [s for s in self.frame_sets if s.complete(self.names)]

    def summary(self) -> dict[str, object]:
        """What ``rigctl take info`` shows, computed from the indexes (right even after a crash)."""
        sets = self.frame_sets
        cams = {}
        for name in self.names:
            idx = self.index[name]
            entry = self.manifest.cameras[name]
            cams[name] = {
                "frames": len(idx),
                "source_drops": len(entry.source_drops) if self.status != "recording" else self._gaps(name),
                "error_frames": len(entry.error_frames),
                "writer_drops": len(entry.writer_drops),
                "not_written": len(entry.not_written),
                "torn_excluded": sum(1 for p in self.problems[name] if p.torn_tail),
            }
        return {
            "take": self.manifest.take,
            "status": self.status,
            "format": f"{self.width}x{self.height} {self.pixel_format} {self.fps:g} fps",
            "cameras": cams,
            "frame_sets": len(sets),
            "complete_sets": sum(1 for s in sets if s.complete(self.names)),
            "skew": framesets.skew_stats(sets),
            "started_utc": self.raw.get("started_utc", ""),
            "end": self.raw.get("end", {}),
            "notes": self.manifest.notes,
        }

    def _gaps(self, name: str) -> int:
        seq = self.index[name]["sequence"].astype(np.int64)
        return int(np.sum(np.clip(np.diff(seq) - 1, 0, None))) if len(seq) > 1 else 0

    @property
    def manifest_model(self) -> Manifest:
        return self.manifest
