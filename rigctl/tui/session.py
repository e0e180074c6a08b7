"""The shoot, without the screen: the rig's devices kept streaming, takes started and stopped, preflight,
tally, camera settings, take marks, and a plain-data snapshot of everything the crew looks at. The UI reads
snapshots; it never touches devices, and nothing here waits on the UI."""

from __future__ import annotations

import collections
import contextlib
import logging
import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rigctl.camera_control import check_settings
from rigctl.capture.preflight import LOW_TIME_S, PreflightReport, WriteSpeed, measure_write
from rigctl.capture.recorder import Recorder, TakePlan
from rigctl.capture.recording import enforce, preflight_take
from rigctl.diskspace import free_bytes
from rigctl.errors import ParameterError, PreflightError, RigctlError
from rigctl.interfaces import SettingResult, SettingState, TallyState
from rigctl.planning.report import plan_rig
from rigctl.registry import DeviceSet, open_cameras, open_control, open_tally
from rigctl.rig import Rig
from rigctl.take.manifest import read_manifest, write_manifest
from rigctl.take.names import next_take_number, take_name
from rigctl.tally import TallyService, tally_state
from rigctl.timecode import start_timecode

log = logging.getLogger(__name__)

STOP_WAIT_S = 12.0  # the recorder gives up on a silent camera after 4 periods, on a lagging one after 10 s


@dataclass
class TileStatus:
    name: str
    row: int
    column: int
    signal: bool = False
    format: str = ""
    format_ok: bool = False
    lock: str = "not reported"
    locked: bool | None = None
    fps: float = 0.0
    source_drops: int = 0
    writer_drops: int = 0
    queue_fill: float = 0.0
    drop_in_s: float | None = None  # writer queue trend: time left before its first writer drop
    age_ms: float | None = None
    stale: bool = False
    tally: str = ""
    mb_s: float = 0.0
    settings: dict[str, SettingResult] = field(default_factory=dict)
    thumbnail: Any = None


@dataclass
class Snapshot:
    rig: str
    tiles: list[TileStatus]
    take: str
    scene: str
    shot: str
    take_number: int
    recording: bool
    busy: str  # "" or what is happening ("arming", "starting", "stopping")
    duration_s: float
    timecode: str
    skew_p50_us: float | None
    skew_p99_us: float | None
    disk_free_gb: float | None
    minutes_left: float | None
    disk_warning: bool
    planner: str
    pair_lights: list[tuple[str, bool]]
    message: str = ""
    last_take: str = ""


def timecode(started_utc: str, fps: float, seconds: float) -> str:
    """The running timecode of a take: its time-of-day start (the ALE's Start) plus the frames since."""
    return str(start_timecode(started_utc, fps) + math.floor(seconds * fps))


class Session:
    """One shooting session on one rig; takes are named ``<scene>-<shot>-T<nn>`` in ``out``."""

    def __init__(self, rig: Rig, out: Path, sim: list[str] | None = None, scene: str = "S01", shot: str = "01") -> None:
        self.rig = rig
        self.out = Path(out)
        self.scene = scene
        self.shot = shot
        self.take_number = next_take_number([self.out], scene, shot)  # on from the takes already there
        self.devices: DeviceSet = open_cameras(rig, sim or [])
        if self.devices.paced:
            self.devices.close()
            raise ParameterError("--sim deterministic=true paces frames by a recorder; the shoot UI shows the rig live")
        self.names = sorted(self.devices.cameras, key=rig.camera_names.index)
        self.period_s = 1.0 / rig.fps
        self.recorder: Recorder | None = None
        self.recording = False
        self.busy = ""
        self.message = ""
        self.last_take = ""
        self.settings: dict[str, dict[str, SettingResult]] = {n: {} for n in self.names}
        self.tally_state = TallyState()
        self._take_lock = threading.Lock()  # start, stop and close one at a time (stop's worker meets quit)
        self.closed = False
        self._speeds: dict[Path, WriteSpeed] = {}  # destination write speed, measured before the cameras stream
        self._skew: collections.deque[float] = collections.deque(maxlen=250)
        self._bytes: dict[str, tuple[float, int]] = {}
        self._disk_t = 0.0
        self._disk_cache: tuple[float | None, float | None] = (None, None)
        self.last_preflight: PreflightReport | None = None
        plan = plan_rig(rig)
        self.planner = (
            f"subject {plan.subject_depth_m:.2f} m deep from {plan.near_m:.2f} m to {plan.far_m:.2f} m; "
            f"every pair within budget from {plan.near_m_all_pairs:.2f} m"
        )
        self.pair_lights = [(p.name, p.within_budget) for p in plan.pairs]
        self.tally: TallyService | None = None
        if rig.model.tally is not None:
            self.tally = TallyService(lambda: open_tally(rig, self.devices), rig.model.tally.port).start()

    # ---- the take ------------------------------------------------------------------------------------
    @property
    def take_name(self) -> str:
        return take_name(self.scene, self.shot, self.take_number)

    def arm(self) -> None:
        """Open the cameras and keep frames flowing (discarded) so tiles are live before anyone records. The
        destination's write speed is measured once, before the first cameras stream: measured later, the
        test competes with the capture threads for the interpreter and reads slow (a false refusal)."""
        self.busy = "arming"
        try:
            if self.out not in self._speeds:
                self.measure()
            rec = Recorder(self.rig, self.devices, TakePlan.spread(self.take_name, [self.out], self.names))
            rec.preview_every_ns = 200_000_000
            rec.arm()
            self.recorder = rec
        finally:
            self.busy = ""

    def measure(self) -> str:
        """Measure the destination's write speed (again); returns what was measured. Measured while the
        cameras stream, the figure can read lower than the disk is (the test shares the interpreter)."""
        with contextlib.suppress(OSError):  # preflight measures again and names the problem
            self._speeds[self.out] = measure_write(self.out)
        speed = self._speeds.get(self.out)
        self.message = f"{self.out}: writes {speed.describe()}" if speed else f"{self.out}: cannot measure"
        return self.message

    def preflight(self) -> list[str]:
        """Reasons not to record that no key can override; empty when every camera is ready. The
        destination's verdict is left in :attr:`last_preflight`."""
        problems = []
        if self.recorder is None:
            return ["the cameras are not streaming (arming failed: see the message line)"]
        want = self.recorder.format
        for name in self.names:
            st = self.devices.cameras[name].status()
            if not st.signal_present:
                problems.append(f"{name}: no signal")
            elif st.format is not None and st.format != want:
                problems.append(f"{name}: delivers {st.format.describe()}, the take needs {want.describe()}")
            if st.reference_locked is False:
                problems.append(f"{name}: reference not locked ({st.extra.get('reference', 'unlocked')})")
        if (self.out / self.take_name).exists():
            problems.append(f"{self.out / self.take_name}: exists; takes are never overwritten")
        with contextlib.suppress(OSError):
            self.out.mkdir(parents=True, exist_ok=True)
        self.last_preflight = preflight_take(self.rig, self.recorder.plan, None, self.recorder.buffers, self._speeds)
        return problems

    def start(self, force: bool = False) -> None:
        """Preflight, then record from the next common frame instant. Raises PreflightError with every reason;
        ``force`` records despite a destination preflight refuses (never despite a camera problem)."""
        with self._take_lock:
            if self.closed:
                raise RigctlError("the session is closed")
            problems = self.preflight()
            report = self.last_preflight
            assert report is not None
            if problems:
                raise PreflightError("; ".join(problems + report.problems), problems + report.problems)
            enforce(report, force)
            assert self.recorder is not None
            self.busy = "starting"
            try:
                self.recorder.start()
                self.recording = True
                self._set_tally(TallyState.recording(self.rig.camera_names))
                self.message = f"recording {self.take_name}" + "".join(f"; {w}" for w in report.warnings)
                if force and not report.ok:
                    self.message += " (recording despite preflight)"
            finally:
                self.busy = ""

    def stop(self) -> str:
        """Stop, finalise the take, and arm again for the next one. Returns the take's folder. Whatever
        happens while finalising, the session leaves the recording state and says what went wrong."""
        with self._take_lock:
            if self.recorder is None or not self.recording:
                return self.last_take
            self.busy = "stopping"
            folder = self.recorder.plan.folder
            try:
                self.recorder.stop()
                # every camera's frames up to the common end instant, not only those already read
                self.recorder.wait(timeout_s=STOP_WAIT_S)
                self.recorder.finish()
                err = self.recorder.error
                self.message = f"{self.take_name} written to {folder}" + (f" ({err})" if err else "")
            except Exception as exc:
                log.exception("finishing %s", folder)
                self.message = f"{self.take_name}: finishing failed ({exc}); frames on disk are kept in {folder}"
                raise
            finally:
                self.recording = False
                self.last_take = str(folder)
                self.take_number += 1
                self._set_tally(TallyState())
                self.busy = ""
            if not self.closed:
                self.arm()
            return self.last_take

    def mark(self, verdict: str, note: str = "") -> str:
        """Mark the last take circled or no-good, with a note, in its manifest."""
        if not self.last_take:
            raise RigctlError("no take to mark yet")
        folder = Path(self.last_take)
        manifest = read_manifest(folder)
        manifest.mark(verdict, note)
        write_manifest(folder, manifest)
        self.message = f"{folder.name} marked {verdict}"
        return self.message

    # ---- rig control ----------------------------------------------------------------------------------
    def _set_tally(self, state: TallyState) -> None:
        self.tally_state = state
        if self.tally is not None:
            self.tally.set(state)

    def set_tally(self, program: list[str], preview: list[str]) -> None:
        if self.recording:
            raise RigctlError("tally follows the take while recording")
        self._set_tally(tally_state(self.rig, program, preview, ("program", "preview")))

    def apply_settings(self, values: dict[str, float | str]) -> list[SettingResult]:
        checked = check_settings(values)
        path = open_control(self.rig, self.devices)
        try:
            results = path.apply(checked, self.names)
        finally:
            path.close()
        for r in results:
            self.settings[r.camera][r.setting] = r
        confirmed = sum(r.state is SettingState.CONFIRMED for r in results)
        self.message = f"camera settings: {confirmed} of {len(results)} confirmed"
        return results

    # ---- what the screen shows --------------------------------------------------------------------------
    def _disk(self) -> tuple[float | None, float | None]:
        now = time.monotonic()
        if now - self._disk_t > 2.0:
            self._disk_t = now
            try:
                self.out.mkdir(parents=True, exist_ok=True)
                free = free_bytes(self.out)
                fmt = self.recorder.format if self.recorder else None
                bps = (fmt.bytes_per_frame * fmt.fps * len(self.names)) if fmt else 0
                self._disk_cache = (free / 1e9, free / bps / 60 if bps else None)
            except OSError:
                self._disk_cache = (None, None)
        return self._disk_cache

    def snapshot(self) -> Snapshot:
        rec = self.recorder
        now_ns = time.monotonic_ns()
        if rec is not None and self.recording:
            rec.sample_queues(now_ns / 1e9)
        tiles = []
        lasts = []
        for name in self.names:
            r, c = self.rig.camera(name).row, self.rig.camera(name).col
            t = TileStatus(name, r, c)
            try:
                st = self.devices.cameras[name].status()
                t.signal = st.signal_present
                t.fps = st.measured_fps
                t.format = st.format.describe() if st.format else "no signal"
                t.format_ok = rec is not None and st.format == rec.format
                t.locked = st.reference_locked
                t.lock = st.extra.get("reference", "locked" if st.reference_locked else "not reported")
            except RigctlError as exc:
                t.format = str(exc)
            if rec is not None:
                cs = rec.stats[name]
                t.source_drops = len(cs.source_drops)
                t.writer_drops = len(cs.writer_drops)
                t.queue_fill = cs.queue_fill
                t.drop_in_s = cs.drop_in_s
                if cs.last_host_ns:
                    t.age_ms = (now_ns - cs.last_host_ns) / 1e6
                    t.stale = t.age_ms > 2000 * self.period_s
                    lasts.append(cs.last_capture_ns)
                t.thumbnail = cs.thumbnail
                prev = self._bytes.get(name)
                now_s = now_ns / 1e9
                if prev is not None and now_s > prev[0]:
                    t.mb_s = (cs.bytes_written - prev[1]) / (now_s - prev[0]) / 1e6
                self._bytes[name] = (now_s, cs.bytes_written)
            t.tally = "PGM" if name in self.tally_state.program else "PVW" if name in self.tally_state.preview else ""
            t.settings = dict(self.settings[name])
            tiles.append(t)
        if len(lasts) > 1:
            period = self.period_s * 1e9
            phases = np.array(lasts, dtype=np.float64) % period
            phases = (phases - phases[0] + period / 2) % period
            self._skew.append(float(phases.max() - phases.min()) / 1e3)
        skew = np.array(self._skew) if self._skew else None
        duration = (now_ns - rec.t0_ns) / 1e9 if (self.recording and rec and rec.t0_ns) else 0.0
        free_gb, minutes = self._disk()
        return Snapshot(
            rig=self.rig.name,
            tiles=tiles,
            take=self.take_name,
            scene=self.scene,
            shot=self.shot,
            take_number=self.take_number,
            recording=self.recording,
            busy=self.busy,
            duration_s=max(0.0, duration),
            timecode=timecode(rec.started_utc if rec else "", self.rig.fps, max(0.0, duration)),
            skew_p50_us=float(np.percentile(skew, 50)) if skew is not None else None,
            skew_p99_us=float(np.percentile(skew, 99)) if skew is not None else None,
            disk_free_gb=free_gb,
            minutes_left=minutes,
            disk_warning=minutes is not None and minutes * 60 < LOW_TIME_S,
            planner=self.planner,
            pair_lights=self.pair_lights,
            message=self.message,
            last_take=self.last_take,
        )

    def close(self) -> None:
        """Stop a take still recording (it is finalised, never lost), the cameras and the tally."""
        with self._take_lock:
            self.closed = True
            if self.recorder is not None:
                if self.recording:
                    self.recorder.stop()
                    self.recording = False
                self.recorder.finish()
                self.recorder = None
            if self.tally is not None:
                self.tally.stop()
            self.devices.close()
