"""Per-camera accounting of a take: what was written, and what was lost where, with sequence numbers."""

from __future__ import annotations

import queue
from dataclasses import dataclass, field
from typing import Any


@dataclass
class CameraStats:
    """Live and final accounting of one camera (read by the UI without locks: plain values only)."""

    name: str
    written: list[tuple[int, int]] = field(default_factory=list)  # (sequence, capture_ns) in write order
    source_drops: list[int] = field(default_factory=list)
    writer_drops: list[int] = field(default_factory=list)
    error_frames: list[int] = field(default_factory=list)
    not_written: list[int] = field(default_factory=list)
    bytes_written: int = 0
    queued: int = 0
    pool_size: int = 0
    last_capture_ns: int = 0
    last_host_ns: int = 0
    last_sequence: int | None = None
    seen_in_window: bool = False
    done: bool = False
    ended: str = ""  # why the stream ended early, if it did
    format_changes: list[int] = field(default_factory=list)
    thumbnail: Any = None  # a small luma image for the shoot UI (uint8 array), when asked for
    preview_ns: int = 0
    first_timecode: Any = None  # rigctl.timecode.Timecode of the first frame written, when frames carry one
    drop_in_s: float | None = None  # time left before the first writer drop at the queue's trend (None: steady)

    @property
    def frames_written(self) -> int:
        return len(self.written)

    @property
    def queue_fill(self) -> float:
        return self.queued / self.pool_size if self.pool_size else 0.0

    def stalled(self, pending: queue.Queue[tuple[Any, int] | None], busy: int | None) -> str:
        """A writer that did not stop in time: the frames still queued for it (and the one it was writing,
        sequence ``busy``) are not written; returns the note that says so."""
        while True:
            try:
                item = pending.get_nowait()
            except queue.Empty:
                break
            if item is not None:
                self.not_written.append(item[0].sequence)
        if busy is not None:
            self.not_written.append(busy)
        n = len(self.not_written)
        return (
            f"writer of {self.name} stalled at stop: {n} frame(s) not written "
            f"(sequences {self.not_written[:10]}{' ...' if n > 10 else ''})"
        )
