"""A simulated take held in memory: the simulator's array (``rigctl.registry.simulated_array``, handed in, so
depth never imports the simulators) as a frame source. Frame set ``n`` shows the scene state the recorder
would have captured at frame ``n``, with camera noise of sequence ``n`` (as the simulated cameras add it),
rectified with the array's true calibration into 8-bit BGR (as ``rigctl rectify`` writes a take), and carries
the exact truth of that state. Every frame, the same bytes on any machine: no clock is involved."""

from __future__ import annotations

from typing import Any

import cv2

from rigctl.depth.grid import Grid, camera_offsets, grid_order, rectified_frame
from rigctl.errors import ParameterError
from rigctl.planning.planner import search_range_px
from rigctl.timecode import Timecode

PLAN_MARGIN_PX = 2.0


class ArrayTake:
    """``frames`` frame sets of a simulated array; ``noise`` False gives the clean rendered state."""

    flat = False
    doffs = 0.0

    def __init__(self, array: Any, frames: int, name: str, noise: bool = True) -> None:
        from rigctl.rectification.rectify import Rectifier

        if frames < 1:
            raise ParameterError(f"a simulated take needs at least one frame set, got {frames}")
        self.array = array
        self.name = name
        self.frames = frames
        self.noise = noise
        self.rect = Rectifier(array.calibration)
        g = self.rect.grid
        self.focal_px = float(g.focal_px)
        self.spacing = float(g.spacing_x_m)
        positions = {n: g.position_m(n) for n in array.names}
        self.offsets = camera_offsets(positions, list(array.names), self.spacing, name)
        self.positions, self.principal = rectified_frame(positions, g.K)
        self.names = grid_order(self.offsets)
        self.disparity_range: tuple[float, float] | None = None

    def planned_range(self) -> tuple[float, float]:
        """What a plan for this scene gives (the simulator's near and far, 2 px margin)."""
        near, far = self.array.near_far()
        return search_range_px(self.focal_px, self.spacing, near, far, PLAN_MARGIN_PX)

    def frame_numbers(self) -> list[int]:
        return list(range(self.frames))

    def timing(self, number: int) -> tuple[float | None, Timecode | None]:
        return float(self.array.fps), None

    def grid(self, number: int) -> Grid:
        from rigctl.pixfmt import to_bgr8

        arr = self.array
        fmt = arr.format
        state = arr.state_of(number)
        raw = arr.frames(state)
        disp, _ = arr.truth(state)
        images = {}
        for i, n in enumerate(arr.names):
            frame = raw[i]
            noise = arr.noise_for(n, number) if self.noise else None
            if noise is not None:
                frame = cv2.add(frame, noise, dtype=cv2.CV_8U)
            images[n] = self.rect.frame(n, to_bgr8(frame, fmt.pixel_format, fmt.width, fmt.height))
        truth = {n: disp[i] for i, n in enumerate(arr.names)}
        return Grid(
            list(self.names),
            {n: images[n] for n in self.names},
            dict(self.offsets),
            self.focal_px,
            self.spacing,
            truth=truth,
            meta={"take": self.name, "frame": number},
            positions=self.positions,
            principal=self.principal,
        )
