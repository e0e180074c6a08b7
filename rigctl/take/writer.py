"""Writing a camera's frames: raw essence appended as captured, then its index record.

Nothing is allocated per frame: the frame is written straight from the capture buffer and the index
record is packed into one reused 64-byte buffer. The frame's CRC-32 (zlib's checksum) is computed by ISA-L,
which at nine 1080p streams costs a few percent of a core where zlib's took most of one. Data is flushed
to the device (fdatasync) at a fixed interval, essence before index, so after a power loss every indexed
frame is either complete or caught by its checksum.
"""

from __future__ import annotations

import contextlib
import errno
import os
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

try:  # ISA-L's CRC-32: the same checksum as zlib's, with carry-less multiply, some 40x faster
    from isal.isal_zlib import crc32
except ImportError:  # pragma: no cover  (a platform without its wheel: zlib's, same values)
    from zlib import crc32

from rigctl.errors import DiskFullError, TakeError
from rigctl.interfaces import Frame, FrameFlags
from rigctl.take import index
from rigctl.take.index import FrameRecord

_TC_FLAGS = int(FrameFlags.TIMECODE | FrameFlags.DROP_FRAME)


def _write_all(fd: int, data: memoryview, path: Path) -> None:
    view = data
    while len(view):
        try:
            n = os.write(fd, view)
        except OSError as exc:
            if exc.errno == errno.ENOSPC:
                raise DiskFullError(f"{path}: destination full (no space left on device)") from None
            raise TakeError(f"{path}: write failed: {exc.strerror}") from None
        view = view[n:]


class CameraWriter:
    """Essence and index files of one camera in a take.

    ``sync_interval_s`` flushes to the device from the writing thread itself; the recorder passes 0 and
    flushes from a separate thread instead (:meth:`sync`), so a slow flush never holds up writing.
    """

    def __init__(self, camera: str, folder: Path, fps: float, checksum: bool = True, sync_interval_s: float = 1.0):
        self.camera = camera
        self.essence_path = folder / f"{camera}.essence"
        self.index_path = folder / f"{camera}.index"
        self.fps = fps
        self.checksum = checksum
        self.sync_interval_s = sync_interval_s
        folder.mkdir(parents=True, exist_ok=True)
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
        try:
            self._essence = os.open(self.essence_path, flags, 0o644)
            self._index = os.open(self.index_path, flags, 0o644)
        except FileExistsError:
            raise TakeError(f"{self.essence_path}: already exists; takes are never overwritten") from None
        self._record = bytearray(index.RECORD_SIZE)
        self._tag = index.camera_tag(camera)  # every record names its camera: swapped files are caught
        self.offset = 0
        self.frames = 0
        self.bytes = 0
        self._last_sync = time.monotonic()

    def write(self, frame: Frame, frame_set: int = -1) -> None:
        data = frame.data
        _write_all(self._essence, data, self.essence_path)
        crc = crc32(data) if self.checksum else 0
        flags = int(frame.flags) & ~_TC_FLAGS
        tc = 0
        if frame.timecode is not None:  # the count goes in as it came; rate and drop flag are the take's
            tc = frame.timecode.frames
            flags |= FrameFlags.TIMECODE | (FrameFlags.DROP_FRAME if frame.timecode.drop else 0)
        index.pack_into(
            self._record,
            frame.sequence,
            frame.capture_ns,
            frame.host_ns,
            flags,
            self.offset,
            len(data),
            crc,
            frame_set,
            tc,
            self._tag,
        )
        _write_all(self._index, memoryview(self._record), self.index_path)
        self.offset += len(data)
        self.frames += 1
        self.bytes += len(data)
        if self.sync_interval_s > 0:
            now = time.monotonic()
            if now - self._last_sync >= self.sync_interval_s:
                self.sync()
                self._last_sync = now

    def sync(self) -> None:
        """Essence before index: an index record on the device implies its frame is there too."""
        os.fdatasync(self._essence)
        os.fdatasync(self._index)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sync()
        os.close(self._essence)
        os.close(self._index)


class TakeWriter:
    """The camera files of a take made from another take (``rigctl rectify``): each processed image is
    appended with its source frame's record copied (sequence, capture and host times, flags, frame set and
    timecode), so the new take's frame sets and timecodes are the source's."""

    def __init__(self, folder: Path, fps: float, checksum: bool = True) -> None:
        self.folder = folder
        self.fps = fps
        self.checksum = checksum
        self.writers: dict[str, CameraWriter] = {}

    def open(self, camera: str) -> CameraWriter:
        """``camera``'s writer, its files created on first use."""
        writer = self.writers.get(camera)
        if writer is None:
            writer = self.writers[camera] = CameraWriter(camera, self.folder, self.fps, self.checksum, 0)
        return writer

    def append(self, camera: str, image: NDArray[np.uint8], source: FrameRecord) -> None:
        """Append ``image`` (any shape, C-contiguous bytes are written as they are) to ``camera``'s files."""
        writer = self.open(camera)
        data = memoryview(np.ascontiguousarray(image).reshape(-1).data)
        frame = Frame(camera, source.sequence, source.capture_ns, source.host_ns, source.flags, data, source.timecode)
        writer.write(frame, source.frame_set)

    def close(self) -> None:
        for writer in self.writers.values():
            writer.close()

    def __enter__(self) -> TakeWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
