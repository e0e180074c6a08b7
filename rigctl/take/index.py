"""The per-frame index of a camera's essence file: fixed 64-byte little-endian records.

A record is written only after its frame's bytes were written, and carries a CRC of itself and of the
frame, so a reader can tell a complete frame from one torn by a crash and never returns a partial frame.

    offset size field
    0      4    magic b"RGIX"
    4      2    version (2; version 1 still read)
    6      2    flags (rigctl.interfaces.FrameFlags)
    8      8    sequence number (device)
    16     8    capture timestamp, ns (CLOCK_MONOTONIC)
    24     8    host timestamp, ns (CLOCK_MONOTONIC)
    32     8    offset of the frame in the essence file
    40     4    size of the frame in bytes
    44     4    CRC-32 of the frame bytes (0 when checksums are off)
    48     4    frame set number assigned at capture (-1: none yet)
    52     4    timecode as frames since midnight (valid when flags has TIMECODE) at the nominal rate of the
                take's fps, drop-frame when flags has DROP_FRAME (rigctl.timecode.Timecode)
    56     4    camera: CRC-32 of the camera's name (``r1c2``) the record belongs to (version 2; 0 in version 1)
    60     4    CRC-32 of bytes 0..59

Version 2 (rigctl 0.x from issue 25 on) names the camera in every record, so a camera's files swapped with
another's, or renamed to another's, are caught by the reader (:func:`rigctl.take.proof.identity_problems`)
although every checksum holds. Version 1 records (older takes, 0 there) still read; such a take cannot prove
which camera its files belong to, and the reader says so once.
"""

from __future__ import annotations

import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import DamagedDataError, TakeError
from rigctl.interfaces import FrameFlags
from rigctl.regular import open_regular, read_regular
from rigctl.timecode import Timecode

MAGIC = b"RGIX"
VERSION = 2  # 1: no camera in the record (still read)
VERSIONS = (1, 2)
RECORD = struct.Struct("<4sHHQqqQIIiII")
assert RECORD.size == 60
RECORD_SIZE = 64
MAX_INDEX_BYTES = RECORD_SIZE << 24  # 16 million frames: 6 days at 30 fps


@dataclass(frozen=True)
class FrameRecord:
    """What a take's index says about one frame, besides where its bytes are: a processed frame copies it."""

    camera: str
    sequence: int
    capture_ns: int
    host_ns: int
    flags: FrameFlags  # without the timecode bits: the timecode is carried in ``timecode``
    frame_set: int
    timecode: Timecode | None


DTYPE = np.dtype(
    [
        ("sequence", "<u8"),
        ("capture_ns", "<i8"),
        ("host_ns", "<i8"),
        ("offset", "<u8"),
        ("size", "<u4"),
        ("crc", "<u4"),
        ("flags", "<u2"),
        ("set", "<i4"),
        ("timecode", "<u4"),
        ("camera", "<u4"),  # camera_tag(name) of the camera the record names (0: a version 1 record)
        ("version", "<u2"),
    ]
)


def camera_tag(name: str) -> int:
    """What a version 2 record holds for camera ``name``: the CRC-32 of its name."""
    return zlib.crc32(name.encode("utf-8"))


def pack_into(
    buf: bytearray,
    seq: int,
    capture_ns: int,
    host_ns: int,
    flags: int,
    offset: int,
    size: int,
    crc: int,
    frame_set: int = -1,
    timecode: int = 0,
    camera: int | None = None,
) -> None:
    """Fill ``buf`` (64 bytes, reused for every frame) with one record: version 2 naming the camera by its
    :func:`camera_tag`, or (``camera`` None) an old version 1 record that names none."""
    version, tag = (1, 0) if camera is None else (VERSION, camera)
    RECORD.pack_into(
        buf, 0, MAGIC, version, flags, seq, capture_ns, host_ns, offset, size, crc, frame_set, timecode, tag
    )
    struct.pack_into("<I", buf, 60, zlib.crc32(memoryview(buf)[:60]))


@dataclass
class IndexProblem:
    """Something wrong at a byte offset of an index file."""

    path: Path
    offset: int
    message: str
    torn_tail: bool = False  # the last record(s) of a file cut short by a crash: excluded, not an error

    def __str__(self) -> str:
        return f"{self.path}: byte {self.offset}: {self.message}"


def read_index(
    path: Path, essence_size: int | None = None, max_records: int | None = None
) -> tuple[NDArray[np.void], list[IndexProblem]]:
    """All valid records of an index file, and the problems found.

    A short or corrupt record at the very end (a write cut by a crash), or a last frame whose bytes are
    not all in the essence file, is a torn tail: excluded and reported as such. Anything wrong before
    the tail is corruption. Only a regular file is read, and an index of more than ``max_records`` records
    (more frames than its essence file can hold) is refused before it is read.
    """
    limit = (max_records + 1) * RECORD_SIZE - 1 if max_records is not None else MAX_INDEX_BYTES
    fd, size = open_regular(path, TakeError, "index file")
    os.close(fd)
    if size > limit:
        raise DamagedDataError(
            f"{path}: byte {limit - limit % RECORD_SIZE}: index of {size:,} bytes holds more records than its essence "
            f"file can hold frames ({limit // RECORD_SIZE:,})"
        )
    data = read_regular(path, limit, TakeError, "index file")
    n = len(data) // RECORD_SIZE
    problems: list[IndexProblem] = []
    if len(data) % RECORD_SIZE:
        problems.append(
            IndexProblem(path, n * RECORD_SIZE, f"{len(data) % RECORD_SIZE} bytes of a cut record", torn_tail=True)
        )
    out = np.zeros(n, dtype=DTYPE)
    good = np.zeros(n, dtype=bool)
    for i in range(n):
        rec = data[i * RECORD_SIZE : (i + 1) * RECORD_SIZE]
        at = i * RECORD_SIZE
        (crc,) = struct.unpack_from("<I", rec, 60)
        if rec[:4] != MAGIC or zlib.crc32(rec[:60]) != crc:
            problems.append(IndexProblem(path, at, "record checksum mismatch", torn_tail=(i == n - 1)))
            continue
        _, version, flags, seq, cap, host, off, size, dcrc, fset, tc, camera = RECORD.unpack_from(rec, 0)
        if version not in VERSIONS:
            problems.append(IndexProblem(path, at, f"record version {version} unknown (this rigctl reads {VERSIONS})"))
            continue
        if essence_size is not None and off + size > essence_size:
            problems.append(
                IndexProblem(
                    path,
                    at,
                    f"frame at essence offset {off} runs past the end of the essence file ({essence_size} bytes)",
                    torn_tail=(i == n - 1),
                )
            )
            continue
        out[i] = (seq, cap, host, off, size, dcrc, flags, fset, tc, camera if version > 1 else 0, version)
        good[i] = True
    return out[good], problems
