"""Reading a take: manifest, per-camera indexes, frames (never a partial one) and frame sets.

Damaged data is never passed on silently. Every frame's CRC is checked as it is read (zlib's CRC-32 runs
at GB/s: ``benchmarks/frame_crc_cost.py``), and a frame the take claims but cannot deliver -- a checksum
that fails, an index record that is corrupt, a frame past the end of its essence file, an empty essence
file, fewer frames than the manifest counts -- raises :class:`~rigctl.errors.DamagedDataError` naming file
and byte offset. With ``skip_damaged`` such frames are left out instead and listed in :attr:`damaged`,
for the caller to put in its output's manifest and exit status. Paths in ``take.yaml`` must resolve
inside the take folder.

Frames come out as the matcher and the exporters want them, from the bytes read once: :meth:`TakeReader.image`
gives 8-bit BGR (packed 4:2:2 converted directly, BT.709), 8-bit grey or float RGB. Each camera's essence file
is opened once and read with ``pread``; :meth:`TakeReader.close` (or ``with``) closes them.
"""

from __future__ import annotations

import logging
import os
import weakref
import zlib
from functools import cached_property
from pathlib import Path
from types import TracebackType
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import DamagedDataError, TakeError
from rigctl.interfaces import BYTES_PER_PIXEL, FrameFlags, stored_frame_bytes
from rigctl.pixfmt import to_bgr8, to_gray8, to_rgb
from rigctl.regular import open_regular
from rigctl.take import framesets, proof
from rigctl.take.index import RECORD_SIZE, FrameRecord, IndexProblem, read_index
from rigctl.take.manifest import DamagedFrame, Manifest, read_manifest
from rigctl.take.reserve import remove_stale_reserves
from rigctl.timecode import Timecode, TimecodeError, rate_of, start_timecode
from rigctl.yuv10 import TEN_BIT_FORMATS

log = logging.getLogger(__name__)

INDEX_SLACK = 4096  # records beyond what the essence holds still read as damage (a cut essence), not refused
ImageKind = Literal["bgr8", "gray8", "float"]
KINDS: tuple[ImageKind, ...] = ("bgr8", "gray8", "float")


def _close_all(fds: dict[str, int]) -> None:
    for fd in fds.values():
        os.close(fd)
    fds.clear()


class TakeReader:
    """A take folder opened for reading. Frames are addressed by camera and position in its index."""

    def __init__(self, folder: Path, skip_damaged: bool = False, prove: bool = True) -> None:
        self.folder = Path(folder)
        self.skip_damaged = skip_damaged
        self.damaged: list[DamagedFrame] = []  # what was left out, with file and byte (skip_damaged)
        self._fds: dict[str, int] = {}  # camera -> its essence file, opened on first read
        self._finalizer = weakref.finalize(self, _close_all, self._fds)
        self.manifest: Manifest = read_manifest(self.folder)
        self.names = list(self.manifest.cameras)
        fmt = self.manifest.format
        self.width, self.height, self.pixel_format, self.fps = fmt.width, fmt.height, fmt.pixel_format, fmt.fps
        self.bytes_per_frame = fmt.bytes_per_frame
        stored = stored_frame_bytes(fmt.pixel_format, fmt.width, fmt.height)
        if stored is None or fmt.bytes_per_frame != stored:
            raise TakeError(
                f"{self.folder / 'take.yaml'}: format {fmt.width}x{fmt.height} {fmt.pixel_format!r} with "
                f"bytes_per_frame {fmt.bytes_per_frame} is not a format rigctl reads "
                f"({', '.join([*BYTES_PER_PIXEL, *TEN_BIT_FORMATS])}; width x height x bytes per pixel, "
                "10-bit formats 20 bits a pixel at an even width)"
            )
        mpath = self.folder / "take.yaml"
        self.proof: list[str] = proof.format_problems(self.manifest, mpath)  # what the take fails to prove
        self._prove(prove)
        period = self.manifest.timing.frame_period_ns
        self.period_ns = period if period is not None and period > 0 else round(1e9 / fmt.fps)
        self.index: dict[str, NDArray[np.void]] = {}
        self.problems: dict[str, list[IndexProblem]] = {}
        self.proof += proof.file_problems(
            self.folder, {n: (self.essence_path(n), self.index_path(n)) for n in self.names}
        )
        self._prove(prove)
        for name in self.names:
            essence = self.essence_path(name)
            if not essence.exists():
                raise TakeError(f"{essence}: essence file of camera {name} is missing")
            fd, size = open_regular(essence, TakeError, f"essence file of camera {name}")
            self._fds[name] = fd  # the file proven regular is the one read
            # an index holds at most a record a frame its essence can hold (and a torn or cut tail): bounded
            idx, problems = read_index(self.index_path(name), size, size // self.bytes_per_frame + INDEX_SLACK)
            self.index[name] = idx
            self.problems[name] = problems
            self._check_claims(name, essence, size)
            self.proof += proof.record_problems(self.index_path(name), idx, self.bytes_per_frame, self.period_ns)
            self.proof += proof.identity_problems(self.index_path(name), idx, name, self.names)
            if self.status != "recording":  # a crashed take's manifest is the one written at its start
                whole = not self.problems[name] and not self.manifest.damaged_skipped
                entry, ipath = self.manifest.cameras[name], self.index_path(name)
                self.proof += proof.sequence_problems(mpath, name, entry, ipath, idx, whole)
            self._prove(prove)
        span = proof.span_problem(self.folder, self.index, self.period_ns)
        self.proof += [span] if span else []
        self._prove(prove)
        self.notice = proof.unproven_identity(self.folder, self.index)  # an older take: read, with a notice
        if self.notice and prove:  # ``take check`` (prove=False) lists it with its other warnings
            log.warning("%s", self.notice)
        if self.status == "recording":  # a take cut off by a crash: free the space its recorder kept
            remove_stale_reserves({self.folder} | {self.essence_path(n).parent.parent for n in self.names})

    def _prove(self, prove: bool) -> None:
        if prove and self.proof:
            raise TakeError(self.proof[0])

    def _check_claims(self, name: str, essence: Path, size: int) -> None:
        """Refuse (or, skipping, record) frames this camera's index or manifest claims but cannot deliver."""
        claimed = self.manifest.cameras[name].frames
        if size == 0 and (claimed or self.problems[name]):
            self._damaged(name, essence, 0, f"essence file of camera {name} is empty, {claimed} frames claimed")
            return
        for p in self.problems[name]:
            if not p.torn_tail:
                self._damaged(name, p.path, p.offset, p.message)
        readable = len(self.index[name])
        if self.status != "recording" and claimed > readable:
            ipath = self.index_path(name)
            self._damaged(
                name,
                ipath,
                readable * RECORD_SIZE,
                f"take.yaml claims {claimed} frames of camera {name}, {readable} readable",
            )

    def _damaged(self, name: str, path: Path, offset: int, message: str, sequence: int | None = None) -> None:
        if not self.skip_damaged:
            raise DamagedDataError(f"{path}: byte {offset}: {message} (--skip-damaged leaves damaged frames out)")
        self.damaged.append(DamagedFrame(camera=name, file=str(path), byte=offset, problem=message, sequence=sequence))

    def close(self) -> None:
        """Close the essence files (reading again opens them again)."""
        _close_all(self._fds)

    def __enter__(self) -> TakeReader:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def _essence_fd(self, name: str) -> int:
        fd = self._fds.get(name)
        if fd is None:
            fd = self._fds[name] = open_regular(self.essence_path(name), TakeError, f"essence file of camera {name}")[0]
        return fd

    @property
    def status(self) -> str:
        return self.manifest.status

    def _resolve(self, text: str, name: str, kind: str) -> Path:
        """A path of the manifest, refused unless it resolves inside the take folder, or is this camera's file
        in the take's folder on another destination (``<dest>/<take>/cameras/<camera>.<kind>``, as the
        recorder writes a take spread over several disks)."""
        if "\0" in text:  # no file system has such a name (and resolving it raises ValueError)
            raise TakeError(f"{self.folder / 'take.yaml'}: cameras.{name}.{kind} {text!r} holds a NUL byte: refused")
        p = self.folder / text
        try:
            real = p.resolve()
        except (RuntimeError, OSError) as exc:  # a symlink loop: RuntimeError up to Python 3.12, OSError after
            why = exc.strerror if isinstance(exc, OSError) else "a loop of symbolic links"
            raise TakeError(f"{p}: {kind} file of camera {name} cannot be resolved: {why}: refused") from None
        try:
            real.relative_to(self.folder.resolve())
        except ValueError:
            if not (
                real.name == f"{name}.{kind}"
                and real.parent.name == "cameras"
                and real.parent.parent.name == self.manifest.take
            ):
                raise TakeError(
                    f"{self.folder / 'take.yaml'}: cameras.{name}.{kind} {text!r} points outside the take folder: "
                    "refused"
                ) from None
        if Path(text).name != f"{name}.{kind}":  # one camera's file is never another's
            raise TakeError(
                f"{self.folder / 'take.yaml'}: cameras.{name}.{kind} {text!r} is not camera {name}'s file "
                f"({name}.{kind}): refused"
            )
        return p

    def essence_path(self, name: str) -> Path:
        return self._resolve(self.manifest.cameras[name].essence, name, "essence")

    def index_path(self, name: str) -> Path:
        path = self._resolve(self.manifest.cameras[name].index, name, "index")
        if not path.exists():
            raise TakeError(f"{path}: index file of camera {name} is missing")
        return path

    def frame_bytes(self, name: str, i: int, verify: bool = True) -> NDArray[np.uint8]:
        """The bytes of frame ``i`` of camera ``name``, exactly as captured, their CRC checked.

        A frame that fails its checksum or is cut short raises :class:`DamagedDataError`, also when
        skipping (the caller leaves it out through :meth:`frame_or_none`)."""
        rec = self.index[name][i]
        size, offset = int(rec["size"]), int(rec["offset"])
        path = self.essence_path(name)
        if size != self.bytes_per_frame:  # checked before a byte is read: a record may claim 4 GiB
            raise DamagedDataError(
                f"{self.index_path(name)}: byte {i * RECORD_SIZE}: frame of {size} bytes, the format needs "
                f"{self.bytes_per_frame}"
            )
        fd, data = self._essence_fd(name), b""
        while len(data) < size:  # a read may return fewer bytes than asked (network and shared filesystems)
            chunk = os.pread(fd, size - len(data), offset + len(data))
            if not chunk:
                break
            data = chunk if not data else data + chunk
        if len(data) != size:
            raise DamagedDataError(f"{path}: byte {offset}: frame of {size} bytes is cut short ({len(data)} read)")
        if verify and rec["crc"] and zlib.crc32(data) != int(rec["crc"]):
            raise DamagedDataError(f"{path}: byte {offset}: frame {int(rec['sequence'])} fails its checksum")
        return np.frombuffer(data, dtype=np.uint8)

    def frame_or_none(self, name: str, i: int) -> NDArray[np.uint8] | None:
        """Frame bytes as :meth:`frame_bytes`; a damaged frame is None when skipping (and listed in
        :attr:`damaged`), an error otherwise."""
        try:
            return self.frame_bytes(name, i)
        except DamagedDataError as exc:
            if not self.skip_damaged:
                raise DamagedDataError(f"{exc} (--skip-damaged leaves damaged frames out)") from None
            rec = self.index[name][i]
            self._damaged(
                name, self.essence_path(name), int(rec["offset"]), str(exc).split(": ", 2)[-1], int(rec["sequence"])
            )
            return None

    def convert(self, data: NDArray[np.uint8], kind: ImageKind) -> NDArray[np.uint8] | NDArray[np.float32]:
        """A frame's bytes as ``kind``: ``bgr8`` (H x W x 3), ``gray8`` (H x W, full-range BT.709 luma) or
        ``float`` (RGB float32 in [0, 1]); each straight from the captured pixel format."""
        if kind == "bgr8":
            return to_bgr8(data, self.pixel_format, self.width, self.height)
        if kind == "gray8":
            return to_gray8(data, self.pixel_format, self.width, self.height)
        if kind == "float":
            return to_rgb(data, self.pixel_format, self.width, self.height)
        raise TakeError(f"unknown image kind {kind!r} ({', '.join(KINDS)})")

    def image(self, camera: str, index: int, kind: ImageKind = "bgr8") -> NDArray[np.uint8] | NDArray[np.float32]:
        """Frame ``index`` of ``camera`` as ``kind`` (see :meth:`convert`); a damaged frame raises."""
        return self.convert(self.frame_bytes(camera, index), kind)

    def image_or_none(
        self, camera: str, index: int, kind: ImageKind = "bgr8"
    ) -> NDArray[np.uint8] | NDArray[np.float32] | None:
        """As :meth:`image`, None for a damaged frame when skipping (see :meth:`frame_or_none`)."""
        data = self.frame_or_none(camera, index)
        return None if data is None else self.convert(data, kind)

    def frame_rgb(self, name: str, i: int) -> NDArray[np.float32]:
        """Frame ``i`` of ``name`` as RGB float32 in [0, 1] (converted from the captured pixel format)."""
        return to_rgb(self.frame_bytes(name, i), self.pixel_format, self.width, self.height)

    def frame_rgb_or_none(self, name: str, i: int) -> NDArray[np.float32] | None:
        """As :meth:`frame_rgb`, None for a damaged frame when skipping (see :meth:`frame_or_none`)."""
        data = self.frame_or_none(name, i)
        return None if data is None else to_rgb(data, self.pixel_format, self.width, self.height)

    def record(self, name: str, i: int) -> FrameRecord:
        """Frame ``i``'s index record of camera ``name``: what :meth:`TakeWriter.append` copies."""
        rec = self.index[name][i]
        flags = FrameFlags(int(rec["flags"])) & ~(FrameFlags.TIMECODE | FrameFlags.DROP_FRAME)
        return FrameRecord(
            name,
            int(rec["sequence"]),
            int(rec["capture_ns"]),
            int(rec["host_ns"]),
            flags,
            int(rec["set"]),
            self.timecode(name, i),
        )

    @cached_property
    def frame_sets(self) -> list[framesets.FrameSet]:
        """Frame sets assembled from the indexes (the same rule the recorder used)."""
        stamps = {n: self.index[n]["capture_ns"].astype(np.int64) for n in self.names}
        try:
            timecodes = framesets.timecode_counts(self.index, self.fps)
        except TimecodeError as exc:
            raise TakeError(f"{self.folder}: {exc}") from None
        if timecodes is not None and not all(np.all(np.diff(tc) > 0) for tc in timecodes.values()):
            # timecodes that repeat or go back (a damaged index): capture times still order frames
            log.warning(
                "%s: timecodes do not increase in every index; frame sets assembled by capture time", self.folder
            )
            timecodes = None
        if timecodes is not None:
            self._check_timecode_span(timecodes)
        t0 = self.manifest.timing.t0_ns
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
        return start_timecode(self.manifest.started_utc, self.fps) + fs.number

    def _check_timecode_span(self, timecodes: dict[str, NDArray[np.int64]]) -> None:
        """Frame sets by timecode make one slot per timecode from the first to the last: a damaged or hostile
        index whose timecodes span far more than its frames would ask for billions of them."""
        used = [tc for tc in timecodes.values() if len(tc)]
        span = max(int(tc.max()) for tc in used) - min(int(tc.min()) for tc in used) + 1
        frames = sum(len(tc) for tc in used)
        if span > 4 * frames + 1000:
            raise DamagedDataError(
                f"{self.folder}: the indexes' timecodes span {span} frames for {frames} frames recorded: "
                "an index is damaged"
            )

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
            # what the essence takes a second (10-bit: 20 bits a pixel), per camera and for the array
            "data_rate": {
                "camera_bytes_per_s": round(self.bytes_per_frame * self.fps),
                "array_bytes_per_s": round(self.bytes_per_frame * self.fps * len(self.names)),
                "bits_per_pixel": self.bytes_per_frame * 8 / (self.width * self.height),
            },
            "started_utc": self.manifest.started_utc,
            "end": self.manifest.end.model_dump() if self.manifest.end else {},
            "notes": self.manifest.notes,
        }

    def _gaps(self, name: str) -> int:
        seq = self.index[name]["sequence"].astype(np.int64)
        return int(np.sum(np.clip(np.diff(seq) - 1, 0, None))) if len(seq) > 1 else 0
