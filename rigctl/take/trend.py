"""Falling behind, seen before it happens: the trend of a writer queue gives the time left before the first
writer drop (the queue holds as many frames as the camera's buffer pool; a full pool drops frames)."""

from __future__ import annotations

import collections
import logging

log = logging.getLogger(__name__)

MIN_SLOPE = 0.5  # frames/s of growth below which a queue is taken as steady (noise of one frame in 2 s)


class QueueTrend:
    """Queue depth samples over a sliding window; the least-squares slope says how fast the queue grows."""

    def __init__(self, capacity: int, window_s: float = 3.0, min_span_s: float = 1.0) -> None:
        self.capacity = capacity
        self.window_s = window_s
        self.min_span_s = min_span_s
        self.samples: collections.deque[tuple[float, int]] = collections.deque()

    def add(self, t_s: float, queued: int) -> None:
        self.samples.append((t_s, queued))
        while self.samples and t_s - self.samples[0][0] > self.window_s:
            self.samples.popleft()

    def slope(self) -> float | None:
        """Growth in frames per second over the window; None until it spans ``min_span_s``."""
        if len(self.samples) < 3 or self.samples[-1][0] - self.samples[0][0] < self.min_span_s:
            return None
        n = len(self.samples)
        mt = sum(t for t, _ in self.samples) / n
        mq = sum(q for _, q in self.samples) / n
        var = sum((t - mt) ** 2 for t, _ in self.samples)
        if var <= 0:
            return None
        return sum((t - mt) * (q - mq) for t, q in self.samples) / var

    def seconds_to_full(self) -> float | None:
        """Time left before the queue is full (the first writer drop) at the current trend; None when the
        queue is steady or shrinking, 0 when it is full already."""
        if not self.samples:
            return None
        last = self.samples[-1][1]
        if last >= self.capacity:
            return 0.0
        s = self.slope()
        if s is None or s < MIN_SLOPE:
            return None
        return (self.capacity - last) / s
