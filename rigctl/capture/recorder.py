"""The recorder: every camera of a rig to disk at full rate, nothing lost, everything accounted for.

Per camera, a capture thread reads frames from the device into a fixed pool of preallocated buffers and
hands them to that camera's writer thread through a bounded queue. Capture never waits for the writer
or the UI: when no buffer is free the frame is still taken from the device (so the device keeps
flowing) and counted as a writer drop with its sequence number. Sequence gaps are source drops; frames
the device flags as corrupted are error frames. Recording starts at one instant T0 for all cameras and
ends at T1; frame sets are assembled by capture time afterwards (see :mod:`rigctl.take.framesets`).
A paced source (``--sim deterministic=true``) is waited for instead: :mod:`rigctl.capture.pacing`."""

from __future__ import annotations

import dataclasses
import datetime as dt
import logging
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path

from rigctl.capture.pacing import Pacing
from rigctl.errors import DeviceError, RigctlError, TakeError
from rigctl.interfaces import Camera, CaptureFormat, Frame, FrameFlags
from rigctl.registry import DeviceSet
from rigctl.rig import Rig
from rigctl.take.accounting import CameraStats
from rigctl.take.build import TakeState, finalise, take_manifest, thumbnail
from rigctl.take.manifest import End, Manifest, write_manifest
from rigctl.take.plan import FramePool, TakePlan
from rigctl.take.reserve import create_reserve, release_reserve
from rigctl.take.staging import Staging
from rigctl.take.trend import QueueTrend
from rigctl.take.writer import CameraWriter, DiskFullError
from rigctl.yuv10 import Repacker, is_ten_bit

log = logging.getLogger(__name__)

RESERVE_BYTES = 1 << 20  # kept free on every destination so the manifest can be written when it fills


class Recorder:
    """Records one take from an opened :class:`DeviceSet`."""

    def __init__(
        self,
        rig: Rig,
        devices: DeviceSet,
        plan: TakePlan,
        *,
        checksum: bool = True,
        buffers_per_camera: int | None = None,
        stop_timeout_s: float = 5.0,
        writer_factory: Callable[..., CameraWriter] = CameraWriter,
        notes: list[str] | None = None,
    ) -> None:
        self.rig = rig
        self.devices = devices
        self.plan = plan  # where the take is published at its end; recorded under hidden names until then
        self.staging = Staging(plan)
        self.cameras: dict[str, Camera] = devices.cameras
        self.names = sorted(self.cameras, key=lambda n: rig.camera_names.index(n))
        self.format = self.capture_format(rig)
        self.period_ns = round(1e9 / rig.fps)
        self.pace = Pacing(devices.paced)
        self.checksum = checksum
        self.buffers = buffers_per_camera or self.default_buffers(self.format)
        self.stop_timeout_s = stop_timeout_s
        self.writer_factory = writer_factory
        self.notes = list(notes or [])
        self.stats = {n: CameraStats(n, pool_size=self.buffers) for n in self.names}
        self.trends = {n: QueueTrend(self.buffers) for n in self.names}
        self._trend_lock = threading.Lock()
        self.t0_ns: int | None = None
        self.t1_ns: int | None = None
        self.started_utc = ""
        self.error: RigctlError | None = None
        self.end_reason = ""
        self._stop = threading.Event()
        self._capturing = threading.Event()
        self._armed = False
        self._threads: list[threading.Thread] = []
        self._queues: dict[str, queue.Queue[tuple[Frame, int] | None]] = {}
        self._pools: dict[str, FramePool] = {}
        self._writers: dict[str, CameraWriter] = {}
        self._writer_busy: dict[str, Frame | None] = {}
        self._writer_threads: dict[str, threading.Thread] = {}
        self._packers: dict[str, Repacker] = {}  # 10-bit: each writer's repacking to 20 bits a pixel
        self._syncer: threading.Thread | None = None
        self._reserves: dict[Path, int] = {}  # destination -> locked .reserve descriptor
        self._lock = threading.Lock()
        self._finished = threading.Event()
        self._finish_lock = threading.Lock()
        self._final: Manifest | None = None  # None: no take was started
        self._finish_done = False
        self.sync_interval_s = 1.0
        self.preview_every_ns = 0  # > 0: keep a small luma thumbnail per camera this often (the shoot UI)

    @staticmethod
    def capture_format(rig: Rig) -> CaptureFormat:
        return CaptureFormat(rig.width_px, rig.height_px, rig.model.format.pixel_format, rig.fps)

    @staticmethod
    def default_buffers(fmt: CaptureFormat, budget_bytes: int = 3 << 30, cameras: int = 9) -> int:
        """Buffers per camera: a second of frames to ride out a slow flush, within a memory budget."""
        per_second = max(8, round(fmt.fps))
        affordable = budget_bytes // max(cameras * fmt.bytes_per_frame, 1)
        return int(max(4, min(per_second, affordable)))

    # ---- arming -----------------------------------------------------------------------------------
    def arm(self) -> None:
        """Open, configure and start every camera; frames flow (and are discarded) until :meth:`start`."""
        negotiated: dict[str, CaptureFormat] = {}
        try:
            for name in self.names:
                cam = self.cameras[name]
                cam.open()
                negotiated[name] = cam.configure(self.format)
        except RigctlError:
            self.devices.close()
            raise
        silent = [n for n in self.names if not self.cameras[n].status().signal_present]
        if silent:
            self.devices.close()
            where = ", ".join(f"{n} ({self.rig.camera(n).device})" for n in silent)
            raise DeviceError(f"no signal on {where}: check the camera, its SDI cable and the capture input")
        different = {n: f for n, f in negotiated.items() if f != self.format}
        if different:
            self.devices.close()
            first = next(iter(different))
            raise DeviceError(
                f"camera {first} delivers {different[first].describe()}, the rig asks for {self.format.describe()}"
            )
        for name in self.names:
            self._pools[name] = FramePool(self.buffers, self.format.bytes_per_frame)
            self._queues[name] = queue.Queue(maxsize=self.buffers)
            if is_ten_bit(self.format.pixel_format):  # its kernel compiled (or loaded) now, not on a frame
                self._packers[name] = Repacker(self.format.pixel_format, self.format.width, self.format.height)
        for name in self.names:
            self.cameras[name].start()
        self._capturing.set()
        for name in self.names:
            t = threading.Thread(target=self._capture, args=(name,), name=f"capture-{name}", daemon=True)
            t.start()
            self._threads.append(t)
        self._armed = True

    # ---- the take ---------------------------------------------------------------------------------
    def start(self, frames: int | None = None, lead_periods: int = 3) -> None:
        """Create the take and record from the next common instant T0 (``frames`` frame sets, or until
        :meth:`stop`)."""
        if not self._armed:
            raise TakeError("recorder not armed")
        self._create_take()
        phase = self.pace.grid_phase(list(self.stats.values()), self.period_ns)  # every camera delivers
        now = self.pace.now(self.stats.values())
        first_slot = now + lead_periods * self.period_ns
        # T0 half a period before a grid instant: every camera's first stored frame is then in one slot
        grid = first_slot + ((phase - first_slot) % self.period_ns)
        self.t0_ns = grid - self.period_ns // 2
        self.t1_ns = self.t0_ns + frames * self.period_ns if frames else None
        self.started_utc = dt.datetime.now(dt.UTC).isoformat(timespec="milliseconds")
        write_manifest(self.staging.plan.folder, take_manifest(self._state(), "recording"))
        self.pace.place()

    def _create_take(self) -> None:
        staged = self.staging.plan
        folder = staged.folder
        try:
            self.staging.create()  # refused when the name is taken or being recorded
            for name in self.names:
                staged.camera_folders[name].mkdir(parents=True, exist_ok=True)
            for dest in {p.parent for p in staged.camera_folders.values()} | {folder}:
                self._reserves[dest] = create_reserve(dest, RESERVE_BYTES)  # locked: see take/reserve.py
        except OSError as exc:
            raise TakeError(f"{folder}: cannot create the take: {exc.strerror}") from None
        for name in self.names:
            self._writers[name] = self.writer_factory(
                name, staged.camera_folders[name], self.format.fps, checksum=self.checksum, sync_interval_s=0
            )
            self._writer_busy[name] = None
            t = threading.Thread(target=self._write, args=(name,), name=f"writer-{name}", daemon=True)
            t.start()
            self._writer_threads[name] = t
        self._syncer = threading.Thread(target=self._sync_loop, name="syncer", daemon=True)
        self._syncer.start()

    def _sync_loop(self) -> None:
        """Flush every camera's files to the device once a second, off the writers' threads."""
        while not self._finished.wait(self.sync_interval_s):
            for name, writer in list(self._writers.items()):
                try:
                    writer.sync()
                except OSError as exc:
                    log.warning("flushing %s: %s", name, exc.strerror)

    def stop(self) -> None:
        """End the take at the next common instant (frames captured before it are kept), also one of a
        planned length (Ctrl-C during ``rigctl record --seconds``)."""
        if self.t0_ns is not None:
            now = self.pace.now(self.stats.values())
            end = max(self.t0_ns, now + ((self.t0_ns - now) % self.period_ns))
            if self.t1_ns is None or end < self.t1_ns:
                self.t1_ns = end
        self._stop.set()

    def wait(
        self,
        timeout_s: float | None = None,
        progress: Callable[[float], None] | None = None,
        watch: Callable[[float | None], None] | None = None,
        watch_every_s: float = 0.25,
    ) -> bool:
        """Wait until every camera passed T1 (or ended, or the take failed); True when finished. ``watch``
        gets the time left before the first writer drop (:meth:`sample_queues`) every ``watch_every_s``."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        next_watch = 0.0
        while True:
            if watch is not None and time.monotonic() >= next_watch:
                next_watch = time.monotonic() + watch_every_s
                watch(self.sample_queues())
            if self.error is not None:
                return True
            if self.t1_ns is not None:
                now = self.pace.now(self.stats.values())
                if all(s.done or s.ended or self._given_up(s, now) for s in self.stats.values()):
                    return True
                if progress and self.t0_ns is not None:
                    progress(min(1.0, max(0.0, (now - self.t0_ns) / max(self.t1_ns - self.t0_ns, 1))))
            if deadline is not None and time.monotonic() > deadline:
                return False
            time.sleep(0.02)

    def _given_up(self, st: CameraStats, now: int) -> bool:
        """Past T1, stop waiting for a camera gone quiet (lost signal) or far behind (paced: silent a while)."""
        assert self.t1_ns is not None
        if self.pace.paced:
            return self.pace.stale(st.name)
        past = now - self.t1_ns
        quiet = now - st.last_host_ns > 500_000_000 if st.last_host_ns else True
        return (past > 4 * self.period_ns and quiet) or past > 10_000_000_000

    def sample_queues(self, now_s: float | None = None) -> float | None:
        """Add every writer queue's depth to its trend; returns the least time left before a camera's first
        writer drop (None: no queue is growing). Each camera's figure is kept in its stats for the UI."""
        now = time.monotonic() if now_s is None else now_s
        with self._trend_lock:
            for name in self.names:
                trend = self.trends[name]
                trend.add(now, self.stats[name].queued)
                self.stats[name].drop_in_s = trend.seconds_to_full()
        left = [s.drop_in_s for s in self.stats.values() if s.drop_in_s is not None]
        return min(left) if left and not self.pace.paced else None  # paced, a full queue drops nothing

    # ---- threads ----------------------------------------------------------------------------------
    def _in_window(self, t: int) -> int:
        """-1 before T0, 0 inside the take, 1 at or after T1."""
        t0, t1 = self.t0_ns, self.t1_ns
        if t0 is None or t < t0:
            return -1
        if t1 is not None and t >= t1:
            return 1
        return 0

    def _capture(self, name: str) -> None:
        cam = self.cameras[name]
        pool = self._pools[name]
        q = self._queues[name]
        st = self.stats[name]
        while self._capturing.is_set():
            slot = self.pace.slot(pool, self._capturing)
            into = pool.scratch if slot is None else pool.views[slot]
            try:
                frame = cam.read(0.2, into)
            except RigctlError as exc:
                st.ended = str(exc)
                log.error("camera %s: %s", name, exc)
                if slot is not None:
                    pool.give(slot)
                return
            if frame is None:
                if slot is not None:
                    pool.give(slot)
                continue
            self._account_gap(st, frame)
            st.last_capture_ns, st.last_host_ns, st.last_sequence = frame.capture_ns, frame.host_ns, frame.sequence
            if self.preview_every_ns and frame.host_ns - st.preview_ns >= self.preview_every_ns:
                # a few hundred bytes, copied before the buffer is reused
                st.thumbnail = thumbnail(frame.data, self.format)
                st.preview_ns = frame.host_ns
            self.pace.seen(name)
            self.pace.hold(self._capturing)  # paced: the first frame waits for T0 to be decided
            where = self._in_window(frame.capture_ns)
            if where != 0:
                if slot is not None:
                    pool.give(slot)
                if where > 0:
                    st.done = True
                    if self.pace.paced:
                        return  # nothing more is needed, and a paced camera would deliver at once
                continue
            st.seen_in_window = True
            if frame.flags & FrameFlags.FORMAT_CHANGED:
                st.format_changes.append(frame.sequence)
            if frame.flags & FrameFlags.ERROR:
                st.error_frames.append(frame.sequence)
                if slot is not None:
                    pool.give(slot)
                continue
            if self.error is not None:  # the take already failed (e.g. disk full): nothing more is stored
                if slot is not None:
                    pool.give(slot)
                st.done = True
                continue
            if slot is None:
                st.writer_drops.append(frame.sequence)
                continue
            st.queued += 1
            q.put_nowait((frame, slot))  # never blocks: the queue holds as many entries as the pool

    def _account_gap(self, st: CameraStats, frame: Frame) -> None:
        """Sequence numbers skipped since the last frame are source drops, when they fall in the take."""
        last = st.last_sequence
        if last is None or frame.sequence <= last + 1:
            return
        missing = frame.sequence - last - 1
        for k in range(1, missing + 1):
            t = st.last_capture_ns + k * self.period_ns
            if self._in_window(t) == 0:
                st.source_drops.append(last + k)

    def _write(self, name: str) -> None:
        q = self._queues[name]
        pool = self._pools[name]
        st = self.stats[name]
        writer = self._writers[name]
        while True:
            item = q.get()
            if item is None:
                return
            frame, slot = item
            if self.error is not None:
                st.not_written.append(frame.sequence)
                st.queued -= 1
                pool.give(slot)
                continue
            self._writer_busy[name] = frame
            try:
                if name in self._packers:
                    frame = dataclasses.replace(frame, data=self._packers[name](frame.data))
                writer.write(frame)
                if not st.written:
                    st.first_timecode = frame.timecode
                st.written.append((frame.sequence, frame.capture_ns))
                st.bytes_written += len(frame.data)
            except RigctlError as exc:
                st.not_written.append(frame.sequence)
                with self._lock:
                    if self.error is None:
                        self.error = exc
                        self.end_reason = "disk full" if isinstance(exc, DiskFullError) else "write failed"
                        log.info("%s", exc)  # the CLI reports it once, as the error of the take
                self._stop.set()
            finally:
                self._writer_busy[name] = None
                st.queued -= 1
                pool.give(slot)

    # ---- ending -----------------------------------------------------------------------------------
    def finish(self) -> Manifest | None:
        """Stop capture, drain writers (bounded in time), assemble frame sets, write sidecars, truth and
        the final manifest. Returns the manifest (None when no take was started). Safe to call again, from
        any thread: a second caller waits for the first and gets the same manifest (the shoot UI's stop and
        its quit can meet here)."""
        with self._finish_lock:
            if not self._finish_done:
                self._final = self._finish()
                self._finish_done = True
            return self._final

    def _finish(self) -> Manifest | None:
        self._capturing.clear()
        for t in self._threads:
            t.join(timeout=2.0)
        for cam in self.cameras.values():
            try:
                cam.stop()
            except RigctlError as exc:
                log.warning("stopping %s: %s", cam.name, exc)
        if not self._writers:  # never started a take
            self.devices.close()
            self.staging.discard()  # made, if at all, by this run: nothing in it
            return None
        for name in self.names:
            self._queues[name].put(None)
        deadline = time.monotonic() + self.stop_timeout_s
        stalled = []
        for name, t in self._writer_threads.items():
            t.join(timeout=max(0.0, deadline - time.monotonic()))
            if t.is_alive():
                stalled.append(name)
        for name in stalled:
            busy = self._writer_busy.get(name)
            self.notes.append(self.stats[name].stalled(self._queues[name], None if busy is None else busy.sequence))
        self._finished.set()
        if self._syncer is not None:  # a flush in progress must end before its files are closed
            self._syncer.join(timeout=max(1.0, deadline - time.monotonic()))
        for name, writer in self._writers.items():
            if name not in stalled:
                writer.close()
        self.devices.close()
        for dest, fd in self._reserves.items():
            release_reserve(dest, fd)
        if not self.end_reason:
            self.end_reason = "stopped" if self._stop.is_set() else "frames reached"
        if stalled and self.error is None:
            self.end_reason = "stopped with a stalled writer"
        # frame sets, then the manifest, sidecars and ground truth (rigctl.take.build.finalise)
        status = "complete" if self.error is None and not stalled and self.end_reason == "frames reached" else "ended"
        written = any(st.written for st in self.stats.values())
        self.error = self.staging.settle(written, self.error)  # no frame: nothing kept (the error says so)
        if not written:
            return None
        end = End(reason=self.end_reason, message=str(self.error) if self.error else "")
        index_paths = {n: w.index_path for n, w in self._writers.items()}
        disk_full = isinstance(self.error, DiskFullError)
        manifest = finalise(self._state(), index_paths, status, end, self.devices.truth, disk_full)
        self.staging.publish()  # the take appears under its name whole, or (killed before) stays hidden
        return manifest

    def _state(self) -> TakeState:
        return TakeState(
            self.plan.name,
            self.staging.plan.folder,
            self.staging.plan.camera_folders,
            self.names,
            self.rig,
            self.format,
            self.period_ns,
            self.checksum,
            self.devices.description,
            self.devices.settings,
            self.stats,
            self.notes,
            self.started_utc,
            self.t0_ns,
            self.t1_ns,
            self.pace.clock,
            self.plan.camera_folders,
        )
