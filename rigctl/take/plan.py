"""Where a take goes (:class:`TakePlan`) and the fixed pool of frame buffers each camera captures into
(:class:`FramePool`): the recorder's two plain building blocks."""

from __future__ import annotations

import mmap
import queue
from dataclasses import dataclass
from pathlib import Path


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
