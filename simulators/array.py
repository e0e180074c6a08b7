"""The simulated array: true cameras, rendered frames, timing, and the ground truth behind them.

One :class:`SimArray` serves every ``sim://`` camera of a rig. It draws each camera's true pose and lens
from the seed (mounting errors, focal spread, principal point, distortion), renders each distinct scene
state once for all cameras, and knows for every delivered frame which scene state it shows, so the ground
truth of a take is exact.

Start-up is fast: the cameras stream as soon as the first state is rendered, and the rest are rendered in
a child process (:mod:`.states`, :mod:`.render_worker`). So that no frame depends on how fast it is, the presenter's
motion joins in on a fixed schedule (``motion_ramp_s``): each further pose of its cycle a few seconds
after the one before, counted in frames on the genlocked grid. Which state a frame shows is a function of
its frame number alone (:meth:`SimArray.state_of`), and the truth follows the same function.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from functools import cached_property
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from rigctl.simulators import scenes, sensor, soft_edges
from rigctl.simulators.raycast import RayCamera, RenderResult, Scene, render
from rigctl.simulators.rays import rays_for
from rigctl.simulators.settings import SimSettings
from rigctl.simulators.states import DiskCache, Frames, StateStore
from rigctl.simulators.timing import SIMULATED_ORIGIN_NS, FrameTiming, frame_timings, start_offset

from rigctl.board import BoardSpec
from rigctl.calibration_model import ArrayCalibration, CameraModel
from rigctl.interfaces import CaptureFormat
from rigctl.rectification.geometry import RectifiedGrid, common_plane
from rigctl.rig import Rig, rig_from_dict

log = logging.getLogger(__name__)

_rays_for = rays_for  # the name the truth views import

F64 = NDArray[np.float64]
NOISE_BANK = 8


class SimArray:
    """All simulated cameras of one rig, sharing one scene, one clock and one render cache."""

    def __init__(self, rig: Rig, settings: SimSettings | None = None) -> None:
        self.rig = rig
        self.requested = settings or SimSettings()
        self.settings = self.requested.effective()
        self.fps = self.settings.fps or rig.fps
        self.period_ns = round(1e9 / self.fps)
        self.names = rig.camera_names
        self.index = {n: i for i, n in enumerate(self.names)}
        self.format = CaptureFormat(rig.width_px, rig.height_px, rig.model.format.pixel_format, self.fps)
        self.board = BoardSpec()
        self._lock = threading.Lock()
        self._rays: dict[tuple[str, bool], RayCamera] = {}
        self._effect_maps: dict[str, NDArray[np.float32]] = {}
        self._truth: dict[int, tuple[list[NDArray[np.float32]], list[NDArray[np.bool_]]]] = {}
        self._backgrounds: dict[tuple[str, bool], RenderResult] = {}
        # camera state that camera control changes (the simulated bridge writes it; frames follow it)
        self.exposure_us = {n: self.settings.exposure_us for n in self.names}
        self.sensor_gain = {n: 1.0 for n in self.names}
        self.control_state: dict[str, dict[tuple[int, int], tuple[float, ...] | str]] = {n: {} for n in self.names}
        ref = rig.model.reference.source if rig.model.reference else "external"
        self.reference_source: dict[str, str] = dict.fromkeys(self.names, ref)
        self.stream_start_ns: int | None = None
        self.resume_grid = 0  # deterministic: the grid slot a stream (re)starts at, after the last one's frames
        self._pictured = False  # the grid's origin was set at the first picture
        self._claimed: set[str] = set()
        self._prime_lock = threading.Lock()
        self._noise_bank: list[NDArray[Any]] | None = None
        self._luts: dict[float, NDArray[np.uint8]] = {}

    # ---- device bookkeeping ------------------------------------------------------------------------
    def claim(self, name: str) -> None:
        from rigctl.errors import DeviceError

        with self._lock:
            if name not in self.index:
                raise DeviceError(f"sim://{name}: no such simulated camera (rig has {', '.join(self.names)})")
            if name in self._claimed:
                raise DeviceError(f"sim://{name}: device is busy (opened by another user)")
            self._claimed.add(name)

    def release(self, name: str) -> None:
        """The genlocked grid keeps running while cameras are closed (as a reference generator does), so
        frame numbers and the motion schedule carry on across takes."""
        with self._lock:
            self._claimed.discard(name)

    def start_stream(self) -> int:
        """The genlocked grid's origin: set by the first camera that starts, shared by all (deterministic:
        a fixed origin on the simulated clock)."""
        with self._lock:
            if self.stream_start_ns is None:
                self.stream_start_ns = SIMULATED_ORIGIN_NS if self.settings.deterministic else time.monotonic_ns()
            return self.stream_start_ns

    def first_picture(self) -> int:
        """The grid's origin once the first picture is ready: moved to now by the first camera about to
        deliver its first frame (every camera asks before its first), kept after that."""
        with self._lock:
            if not self._pictured:
                self._pictured = True
                self.stream_start_ns = time.monotonic_ns()
            assert self.stream_start_ns is not None
            return self.stream_start_ns

    def gain_lut(self, gain: float) -> NDArray[np.uint8]:
        """A 4-channel LUT scaling packed 4:2:2 bytes as RGB would scale by ``gain``."""
        key = round(gain, 4)
        with self._lock:
            lut = self._luts.get(key)
        if lut is None:
            v = np.arange(256, dtype=np.float64)
            y = np.clip(np.rint(16 + (v - 16) * gain), 0, 255)
            c = np.clip(np.rint(128 + (v - 128) * gain), 0, 255)
            order = (c, y, c, y) if self.format.pixel_format == "UYVY" else (y, c, y, c)
            lut = np.stack(order, axis=1).astype(np.uint8).reshape(1, 256, 4)
            with self._lock:
                self._luts[key] = lut
        return lut

    # ---- the true cameras -------------------------------------------------------------------------
    @cached_property
    def calibration(self) -> ArrayCalibration:
        """The true calibration: nominal lattice plus the seed's mounting and lens errors."""
        s = self.settings
        rig = self.rig
        w, h = rig.width_px, rig.height_px
        rng = np.random.default_rng(np.random.SeedSequence([s.seed, 1]))
        cams = {}
        for cam in rig.cameras:
            draw = rng.normal(size=10)
            fx = rig.c0_px * (1 + s.focal_spread * draw[0])
            fy = rig.c0_y_px * (fx / rig.c0_px)
            cx = (w - 1) / 2 + s.principal_offset_px * draw[1] * w / 960
            cy = (h - 1) / 2 + s.principal_offset_px * draw[2] * w / 960
            k1 = s.distortion_k1 + s.distortion_spread * draw[3]
            dist = np.array([k1, -0.3 * k1, 0.0, 0.0, 0.0])
            rvec = np.radians(s.mount_rotation_deg) * draw[4:7]
            R = cv2.Rodrigues(rvec)[0]
            C = np.array([cam.x_m, cam.y_m, 0.0]) + s.mount_position_mm * 1e-3 * draw[7:10]
            K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])
            cams[cam.name] = CameraModel(cam.name, K, dist, R, -R @ C, (w, h))
        ref = "r1c1" if "r1c1" in cams else self.names[0]
        return ArrayCalibration(rig=rig.name, cameras=cams, reference=ref, meta={"source": "simulation truth"})

    @cached_property
    def rectified(self) -> RectifiedGrid:
        return common_plane(self.calibration, self.rig.spacing_m)

    @cached_property
    def _pixel_grid(self) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        h, w = self.rig.height_px, self.rig.width_px
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        return xs, ys

    def rays(self, name: str, rectified: bool = False) -> RayCamera:
        """One camera's rays, computed on first use (cameras in parallel threads each compute their own)."""
        rectified = rectified and not self.settings.ideal  # ideal cameras are rectified already
        key = (name, rectified)
        with self._lock:
            cached = self._rays.get(key)
        if cached is None:
            cam = self.rectified.camera(name) if rectified else self.calibration[name]
            cached = rays_for(cam, self._pixel_grid)
            with self._lock:
                cached = self._rays.setdefault(key, cached)
        return cached

    @cached_property
    def _gains(self) -> dict[str, NDArray[np.float32]]:
        """Per camera: per-channel gain (exposure and colour mismatch), drawn in camera order."""
        s = self.settings
        rng = np.random.default_rng(np.random.SeedSequence([s.seed, 2]))
        out = {}
        for n in self.names:
            d = rng.normal(size=4)
            out[n] = ((1 + s.exposure_spread * d[0]) * (1 + s.colour_spread * d[1:4])).astype(np.float32)
        return out

    @cached_property
    def _vignetting(self) -> NDArray[np.float32]:
        h, w = self.rig.height_px, self.rig.width_px
        xs, ys = self._pixel_grid
        r2 = ((xs - w / 2) ** 2 + (ys - h / 2) ** 2) / ((w / 2) ** 2 + (h / 2) ** 2)
        return (1.0 - self.settings.vignetting * r2).astype(np.float32)

    def _effects(self, name: str) -> NDArray[np.float32]:
        """One camera's vignetting times its gain, H x W x 3 (made in the camera's own render thread)."""
        with self._lock:
            cached = self._effect_maps.get(name)
        if cached is None:
            cached = np.ascontiguousarray(self._vignetting[..., None] * self._gains[name][None, None, :])
            with self._lock:
                self._effect_maps[name] = cached
        return cached

    @property
    def _noise(self) -> list[NDArray[Any]]:
        with self._prime_lock:  # drawn once, by whichever thread needs it first
            if self._noise_bank is None:
                s = self.settings
                self._noise_bank = sensor.noise_bank(s.seed, s.noise, self.format, NOISE_BANK)
            return self._noise_bank

    # ---- scene states -----------------------------------------------------------------------------
    @property
    def distinct_states(self) -> int:
        """How many different scene states a stream cycles through (each is rendered once)."""
        s = self.settings
        if s.scene == "charuco":
            return s.board_poses
        if not s.motion:
            return 1
        return s.motion_states

    @property
    def ramp_frames(self) -> int:
        """Frames between one pose of the presenter's motion joining in and the next (0: all from the start,
        every state rendered before the cameras stream)."""
        s = self.settings
        if s.scene == "charuco" or not s.motion or self.distinct_states == 1:
            return 0
        return round(s.motion_ramp_s * self.fps)

    def state_of(self, scene_frame: int) -> int:
        """Which distinct scene state a frame on the common grid shows: a function of the frame number
        alone, never of how far rendering has got."""
        s = self.settings
        if s.scene == "charuco":
            return (scene_frame // s.board_hold_frames) % s.board_poses
        if not s.motion:
            return 0
        per_cycle = max(1, round(scenes.MOTION_PERIOD_S * self.fps))
        state = (scene_frame % per_cycle) * s.motion_states // per_cycle
        ramp = self.ramp_frames
        # pose k joins at frame k * ramp; until then the cycle holds at the latest pose that has joined
        return min(state, scene_frame // ramp) if ramp else state

    @cached_property
    def board_poses(self) -> list[scenes.BoardPose]:
        half = self.rig.model.sensor.width_mm / (2 * self.rig.model.lens.focal_length_mm)
        return scenes.board_poses(self.settings, self.board, half)

    def scene(self, state: int, dt: float = 0.0) -> Scene:
        """The scene of ``state``, ``dt`` seconds after its instant (motion blur samples the exposure)."""
        if self.settings.scene == "charuco":
            pose = self.board_poses[state]
            # a power of two per square: the texture's mip levels then need no resampling, which would
            # shift corners by a fraction of a texel depending on where they fall
            need = self.rig.c0_px * self.board.square_m / self.settings.board_distance_m[0] * 2
            px = int(2 ** np.clip(np.ceil(np.log2(need)), 5, 9))
            return scenes.charuco(self.settings, self.board, pose, px)
        return scenes.presenter(self.settings, state * scenes.MOTION_PERIOD_S / self.settings.motion_states + dt)

    def _static(self, scene: Scene, name: str, rectified: bool) -> RenderResult:
        """The scene's static background through one camera, rendered once."""
        key = (name, rectified)
        with self._lock:
            cached = self._backgrounds.get(key)
        if cached is None:
            rays = self.rays(name, rectified)
            static = Scene(scene.primitives[: scene.static], scene.light_dir, scene.ambient, scene.background)
            cached = render(static, rays, colour=not rectified)
            with self._lock:
                self._backgrounds[key] = cached
        return cached

    def _render_camera(self, scene: Scene, name: str, state: int) -> NDArray[np.uint8]:
        base = self._static(scene, name, rectified=False)
        res: RenderResult = render(scene, self.rays(name), base=base, skip=scene.static)
        if self.settings.edges == "soft":
            res.rgb = soft_edges.render_soft(self, state, name, res, rectified=False).rgb
        rgb = np.asarray(cv2.multiply(res.rgb, self._effects(name)), dtype=np.float32)
        return sensor.encode(rgb, self.format.pixel_format, self.settings.exposure_stops)

    @cached_property
    def _disk_cache(self) -> DiskCache | None:
        """Rendered states across runs: one folder per rig, settings and simulator source."""
        inputs = [self.rig.to_dict(), self.requested.model_dump(mode="json", exclude={"deterministic"})]
        sources = [
            scenes.__file__,
            __file__,
            sys.modules[render.__module__].__file__,
            sys.modules[rays_for.__module__].__file__,
            soft_edges.__file__,
        ]
        sources.append(sensor.__file__)
        return DiskCache.for_inputs(
            inputs, [Path(m) for m in sources if m], self.names, sensor.clean_bytes(self.format)
        )

    def _render_state(self, state: int) -> Frames:
        # drawn once, before the cameras' threads use them (each camera's rays are its own thread's work)
        self._gains, self._vignetting, self.rectified  # noqa: B018
        with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
            for name in self.names:  # the first time: rays while this thread builds the scene's textures
                pool.submit(self.states.unless_stopped, self.rays, name)
            scene = self.scene(state)
            render = self.states.unless_stopped  # once the array is closed, no camera not yet begun
            return list(pool.map(lambda n: render(self._render_camera, scene, n, state), self.names))

    @cached_property
    def states(self) -> StateStore:
        """Every state's frames, rendered once (in memory, and on disk across runs)."""
        return StateStore(self._render_state, self._disk_cache)

    def frames(self, state: int) -> Frames:
        """Rendered bytes of every camera for one scene state (waits for, or does, its render)."""
        return self.states.get(state)

    @property
    def up_front(self) -> bool:
        """Whether every state is rendered before the cameras stream: a stream that needs them all from its
        first frame (the charuco scene, motion without its ramp) could not be delivered in real time
        otherwise, and a still scene (one state) starts as it always has, its frames from the stream's
        first instant. With the motion's ramp, the cameras stream at once and their first frame waits
        for the first state."""
        return not self.ramp_frames

    def prime(self) -> None:
        """Render what streaming needs before its first frame (:attr:`up_front`) and draw the noise."""
        for state in range(self.distinct_states if self.up_front else 1):
            self.states.get(state)
        if self.settings.noise:
            self._noise  # noqa: B018  (drawn here, not on the first frame)

    def close(self, wait_s: float = 30.0) -> None:
        """Stop rendering in the background, waiting up to ``wait_s`` for the state under way: a process exiting
        while that thread is in OpenCV is aborted by the C++ runtime (exit 134 after the command's error)."""
        self.states.stop()
        self.states.join(wait_s)

    def render_in_background(self) -> None:
        """Start rendering now, in the order frames will need the states: first what streaming needs, here;
        the rest, which is rendered while the cameras stream, in a low-priority process of its own."""
        if self.up_front or self.distinct_states == 1:
            self.states.start(range(self.distinct_states), first=None if self.up_front else self.prime)
            return
        from rigctl.simulators.render_worker import RenderWorker

        disk = self._disk_cache
        cold = disk is None or not all(disk.has(k) for k in range(1, self.distinct_states))
        worker = RenderWorker(
            array_from_json, json.dumps(self.rig.to_dict()), self.requested.model_dump_json(), self.names, eager=cold
        )
        self.states.start(range(self.distinct_states), first=self.prime, render=worker, done=worker.close)

    def truth(self, state: int) -> tuple[list[NDArray[np.float32]], list[NDArray[np.bool_]]]:
        """Per camera: disparity in the rectified geometry of the true calibration (+inf off the subject)
        and the subject matte."""
        with self._lock:
            cached = self._truth.get(state)
        if cached is not None:
            return cached
        scene = self.scene(state)
        disp, mattes = [], []
        for n in self.names:
            base = self._static(scene, n, rectified=True)
            res = render(scene, self.rays(n, rectified=True), colour=False, base=base, skip=scene.static)
            d = self.rectified.disparity_from_depth(res.depth.astype(np.float64)).astype(np.float32)
            d[~res.subject] = np.inf
            disp.append(d)
            mattes.append(res.subject)
        with self._lock:
            self._truth[state] = (disp, mattes)
        return disp, mattes

    # ---- timing -----------------------------------------------------------------------------------
    def timing(self, name: str, first_grid: int = 0) -> Iterator[FrameTiming]:
        """Frame timings of camera ``name`` after it starts streaming at grid slot ``first_grid``
        (:func:`rigctl.simulators.timing.frame_timings`)."""
        offset = start_offset(self.settings, self.names, name, self.period_ns)
        return frame_timings(self.settings, name, self.index[name], self.period_ns, first_grid, offset)

    def signal_present(self, name: str, t_rel_ns: int) -> bool:
        loss = self.settings.signal_loss.get(name)
        return loss is None or not (loss[0] * 1e9 <= t_rel_ns < loss[1] * 1e9)

    def noise_for(self, name: str, sequence: int) -> NDArray[Any] | None:
        if not self.settings.noise:
            return None
        return self._noise[(self.index[name] * 3 + sequence * 5) % NOISE_BANK]

    def gain_for(self, name: str) -> float:
        """Brightness change from camera control (exposure or sensor gain set away from what was rendered)."""
        return self.exposure_us[name] / self.settings.exposure_us * self.sensor_gain[name]

    def reference_locked(self, name: str) -> tuple[bool, str]:
        """Whether the camera is locked to a reference, and how it is set."""
        source = self.reference_source[name]
        if source == "internal":
            return False, "internal (free-running)"
        if not self.settings.reference_present or name in self.settings.unlocked:
            return False, f"{source}, NOT LOCKED"
        return True, f"{source}, locked"

    # ---- ground truth on disk ---------------------------------------------------------------------
    def write_truth_for(
        self, folder: Path, frame_sets: list[tuple[int, dict[str, int]]], delivered: dict[str, dict[int, int]]
    ) -> None:
        """:meth:`write_truth` for frame sets given as {camera: sequence number}."""
        scene_sets = [(n, {c: delivered[c][seq] for c, seq in members.items()}) for n, members in frame_sets]
        self.write_truth(folder, scene_sets)

    def write_truth(self, folder: Path, frame_sets: list[tuple[int, dict[str, int]]]) -> None:
        """Write ``truth/`` (:func:`rigctl.simulators.truth_files.write_truth`): the true calibration, per
        frame set and camera the disparity and the subject matte, and the charuco scene's board poses."""
        from rigctl.simulators.truth_files import write_truth

        write_truth(self, folder, frame_sets)

    def near_far(self) -> tuple[float, float]:
        """Where the presenter's surfaces lie: what a plan for this scene would give."""
        return nominal_near_far(self.settings)

    def frame_period_s(self) -> float:
        return 1.0 / self.fps

    def describe(self) -> str:
        s = self.settings
        return (
            f"simulated {self.rig.name}: scene {s.scene}, seed {s.seed}, {'ideal' if s.ideal else 'realistic'}, "
            f"{self.distinct_states} distinct state{'s' if self.distinct_states != 1 else ''}, "
            f"{self.format.describe()}"
        )


def nominal_near_far(settings: SimSettings) -> tuple[float, float]:
    """Where the presenter's surfaces lie (for tests and the demo's plan)."""
    near = settings.subject_distance_m
    return near, near + scenes.PRESENTER_DEPTH_M


def array_from_json(rig: str, settings: str) -> SimArray:
    """A simulated array from a rig and settings as JSON (what a render process is started with)."""
    return SimArray(rig_from_dict(json.loads(rig)), SimSettings.model_validate_json(settings))
