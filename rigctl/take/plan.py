"""Where a take goes (:class:`TakePlan`) and the fixed pool of frame buffers each camera captures into
(:class:`FramePool`): the recorder's two plain building blocks."""

from __future__ import annotations

import mmap
import os
import queue
from dataclasses import dataclass
from pathlib import Path

from rigctl.errors import ParameterError

# a pool is one mapping per buffer, and a process has at most vm.max_map_count (65530) of them: nine cameras of
# 1024 buffers (41 s at 25 fps) stay far below it
MAX_BUFFERS = 1024


def physical_memory() -> int:
    """Bytes of memory this machine has (0 where it cannot tell)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (OSError, ValueError):
        return 0


def check_buffers(buffers: int, frame_bytes: int, cameras: int, memory: int | None = None) -> int:
    """``buffers`` frame buffers a camera, refused in one line naming ``--buffers`` before any is allocated unless
    it is at least 2 (one written while one is filled), at most :data:`MAX_BUFFERS`, and every camera's pool
    fits in half of the machine's ``memory`` (the pools are preallocated; beyond that the allocation fails, or
    the kernel kills the recorder mid-take as the pages fill)."""
    memory = physical_memory() if memory is None else memory
    fit = memory // 2 // max(frame_bytes * cameras, 1) if memory > 0 else MAX_BUFFERS
    most = max(2, min(MAX_BUFFERS, fit))
    if not 2 <= buffers <= most:
        why = (
            f"the pools of {cameras} camera(s) of {frame_bytes / 1e6:.1f} MB frames within half of this machine's "
            f"{memory / 1e9:.1f} GB of memory"
            if fit < MAX_BUFFERS
            else "a camera's pool is one memory mapping a buffer"
        )
        raise ParameterError(f"--buffers must be 2 to {most} ({why}), got {buffers}")
    return buffers


class FramePool:
    """Preallocated frame buffers of one camera; taking one never blocks."""

    def __init__(self, count: int, size: int) -> None:
        # anonymous maps: the kernel zeroes a page when a frame first lands on it, not all up front (a
        # second's pools of nine cameras would otherwise cost arming half a second), and page-aligned
        self.buffers = [mmap.mmap(-1, size) for _ in range(count)]
        self.views = [memoryview(b) for b in self.buffers]
        self.free: queue.SimpleQueue[int] = queue.SimpleQueue()
        for i in range(count):
            self.free.put(i)
        self.scratch = memoryview(bytearray(size))

    def take(self) -> int | None:
        try:
            return self.free.get_nowait()
        except queue.Empty:
            return None

    def give(self, i: int) -> None:
        self.free.put(i)


@dataclass
class TakePlan:
    """Where a take goes: its name, the primary folder (manifest) and per camera the folder of its files."""

    name: str
    folder: Path
    camera_folders: dict[str, Path]

    @classmethod
    def spread(cls, name: str, destinations: list[Path], cameras: list[str]) -> TakePlan:
        """Cameras dealt round-robin over the destinations; the manifest lives on the first."""
        folders = {cam: destinations[i % len(destinations)] / name / "cameras" for i, cam in enumerate(cameras)}
        return cls(name, destinations[0] / name, folders)
