"""The writer's per-frame checksum is zlib's CRC-32, whichever implementation computes it: takes written
with the fast one verify with zlib, in any reader."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np

from rigctl.interfaces import Frame, FrameFlags
from rigctl.take.index import read_index
from rigctl.take.writer import CameraWriter


def test_every_index_record_carries_zlibs_crc32_of_its_frame(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    # odd sizes and contents too: the fast path's folding must agree at every length and alignment
    frames = [rng.integers(0, 256, n, dtype=np.uint8).tobytes() for n in (4147200, 1, 15, 64, 4097, 100003)]
    writer = CameraWriter("r0c0", tmp_path, 25.0, sync_interval_s=0)
    for seq, data in enumerate(frames):
        writer.write(Frame("r0c0", seq, seq * 40_000_000, seq, FrameFlags.TIMESTAMP_MONOTONIC, memoryview(data)))
    writer.close()
    index, problems = read_index(tmp_path / "r0c0.index")
    assert problems == [] and len(index) == len(frames)
    assert [int(c) for c in index["crc"]] == [zlib.crc32(d) for d in frames]
    # and a changed byte would be caught: the checksum is of the bytes, not a constant
    assert zlib.crc32(frames[0][:-1] + bytes([frames[0][-1] ^ 1])) != int(index["crc"][0])
