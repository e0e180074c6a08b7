"""What the recorder writes besides frames: the take's :class:`~rigctl.take.manifest.Manifest` built from its
accounting, the frame sets assembled from what was written, the sidecar logs, and the shoot UI's thumbnails.

Nothing here touches a device: the recorder hands in its plain accounting (:class:`CameraStats`) and gets
typed values back."""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rigctl import __version__
from rigctl.errors import DiskFullError, OutputError, RigctlError
from rigctl.interfaces import CaptureFormat, TruthProvider
from rigctl.rig import Rig
from rigctl.take import framesets, sidecars
from rigctl.take.accounting import CameraStats
from rigctl.take.index import read_index
from rigctl.take.manifest import (
    TAKE_SPEC,
    CameraEntry,
    Devices,
    End,
    FormatEntry,
    FrameSetSummary,
    IncompleteSet,
    Manifest,
    Rectification,
    Skew,
    Software,
    Timing,
    write_manifest,
)
from rigctl.timecode import start_timecode
from rigctl.yuv10 import TEN_BIT_FORMATS, from_device, is_ten_bit

log = logging.getLogger(__name__)


@dataclass
class TakeState:
    """The recorder's view of a take, as the manifest needs it."""

    name: str
    folder: Path
    camera_folders: dict[str, Path]
    names: list[str]
    rig: Rig
    format: CaptureFormat
    period_ns: int
    checksum: bool
    devices_description: str
    devices_settings: dict[str, object]
    stats: dict[str, CameraStats]
    notes: list[str]
    started_utc: str = ""
    t0_ns: int | None = None
    t1_ns: int | None = None
    clock: str = "CLOCK_MONOTONIC"  # "simulated": a deterministic simulation's times
    published_camera_folders: dict[str, Path] | None = None  # where the camera folders are once published


def camera_entry(state: TakeState, name: str) -> CameraEntry:
    st = state.stats[name]
    cam_folder = state.camera_folders[name]
    rel = os.path.relpath(cam_folder, state.folder)
    # on another destination: the absolute path the take's files have once published (rigctl.take.staging)
    published = (state.published_camera_folders or {}).get(name, cam_folder)
    base = rel if not rel.startswith("..") else os.path.abspath(published)
    return CameraEntry(
        essence=f"{base}/{name}.essence",
        index=f"{base}/{name}.index",
        frames=st.frames_written,
        first_sequence=st.written[0][0] if st.written else None,
        last_sequence=st.written[-1][0] if st.written else None,
        source_drops=sorted(st.source_drops),
        error_frames=list(st.error_frames),
        writer_drops=list(st.writer_drops),
        not_written=list(st.not_written),
        ended_early=st.ended or None,
        format_changed_at=list(st.format_changes) or None,
    )


def frame_set_summary(sets: list[framesets.FrameSet], names: list[str]) -> FrameSetSummary:
    incomplete = [
        IncompleteSet(number=s.number, missing=[c for c in names if c not in s.members])
        for s in sets
        if not s.complete(names)
    ]
    return FrameSetSummary(
        count=len(sets),
        complete=len(sets) - len(incomplete),
        incomplete=incomplete,
        skew=Skew.model_validate(framesets.skew_stats(sets)),
        file="sets.csv",
    )


def take_manifest(
    state: TakeState,
    status: str,
    sets: list[framesets.FrameSet] | None = None,
    end: End | None = None,
    rectification: Rectification | None = None,
) -> Manifest:
    """The manifest of the take as it stands: ``sets`` and ``end`` once it has ended."""
    fmt = state.format
    return Manifest(
        spec=TAKE_SPEC,
        take=state.name,
        status=status,
        started_utc=state.started_utc,
        software=Software(name="rigctl", version=__version__),
        rig=state.rig.to_dict(),
        format=FormatEntry(
            width=fmt.width,
            height=fmt.height,
            pixel_format=fmt.pixel_format,
            fps=fmt.fps,
            bytes_per_frame=fmt.stored_bytes_per_frame,  # 10-bit: 20 bits a pixel, not the device's layout
        ),
        timing=Timing(
            clock=state.clock,
            t0_ns=state.t0_ns,
            t1_ns=state.t1_ns,
            frame_period_ns=state.period_ns,
            start_timecode=start_timecode(state.started_utc, fmt.fps),
        ),
        checksum="crc32" if state.checksum else "none",
        devices=Devices.model_validate({"description": state.devices_description, "settings": state.devices_settings}),
        cameras={n: camera_entry(state, n) for n in state.names},
        notes=list(state.notes),
        frame_sets=None if sets is None else frame_set_summary(sets, state.names),
        end=end,
        rectification=rectification,
    )


def assemble_sets(state: TakeState, index_paths: dict[str, Path]) -> list[framesets.FrameSet]:
    """Frame sets of what was written, by the reader's rule: by timecode (read back from the indexes just
    written) when every camera's frames carry one, else by capture time."""
    names = state.names
    stamps = {n: np.array([c for _, c in state.stats[n].written], dtype=np.int64) for n in names}
    timecodes = None
    if all(state.stats[n].first_timecode is not None for n in names):
        try:
            indexes = {n: read_index(index_paths[n])[0] for n in names}
            if all(len(indexes[n]) == len(stamps[n]) for n in names):
                timecodes = framesets.timecode_counts(indexes, state.format.fps)
        except RigctlError as exc:
            log.warning("frame sets by time, not timecode: %s", exc)
    return framesets.assemble(stamps, state.period_ns, state.t0_ns, timecodes)


def write_sidecars(state: TakeState, sets: list[framesets.FrameSet], devices: dict[str, str]) -> None:
    """``sets.csv``, ``log.csv`` and the ALE beside the manifest (OSError when the destination refuses)."""
    folder, names, stats = state.folder, state.names, state.stats
    start = start_timecode(state.started_utc, state.format.fps)
    sidecars.write_sets_csv(folder / "sets.csv", sets, names, stats, start)
    sidecars.write_log_csv(folder / "log.csv", names, devices, stats)
    sidecars.write_ale(folder / f"{state.name}.ale", state.name, state.started_utc, state.format, names, stats)


def thumbnail(data: memoryview, fmt: CaptureFormat, width: int = 48) -> NDArray[np.uint8] | None:
    """A small luma image of a packed 4:2:2 frame for the shoot UI (a few hundred bytes, copied out of the
    capture buffer before it is reused); None for other formats or a short frame."""
    if fmt.pixel_format not in ("UYVY", "YUYV", *TEN_BIT_FORMATS) or len(data) < fmt.bytes_per_frame:
        return None
    step = max(1, fmt.width // width)
    if is_ten_bit(fmt.pixel_format):  # only the rows shown are decoded; 8-bit codes for the screen
        lines = np.frombuffer(data, np.uint8, count=fmt.bytes_per_frame).reshape(fmt.height, -1)[:: 2 * step]
        codes = from_device(lines, fmt.pixel_format, fmt.width, lines.shape[0])
        return np.ascontiguousarray(codes[:, 1 :: 2 * step] >> 2).astype(np.uint8)
    packed = np.frombuffer(data, np.uint8, count=fmt.bytes_per_frame).reshape(fmt.height, fmt.width * 2)
    start = 1 if fmt.pixel_format == "UYVY" else 0
    return np.ascontiguousarray(packed[:: 2 * step, start :: 2 * step])


def finalise(
    state: TakeState,
    index_paths: dict[str, Path],
    status: str,
    end: End,
    truth: TruthProvider | None,
    disk_full: bool,
) -> Manifest:
    """The end of a take: the manifest goes first (the recorder just freed the reserve for it), then what can
    be rebuilt or lost without losing the take: sidecars and ground truth. A simulation whose frames are
    already rectified (ideal) gives the manifest its rectification section. Problems become notes (in
    ``state.notes``) and the manifest is written again with them."""
    sets = assemble_sets(state, index_paths)
    folder = state.folder
    rectification = truth.rectification() if truth is not None else None
    write_manifest(folder, take_manifest(state, status, sets, end, rectification))
    extras_failed = False
    try:
        write_sidecars(state, sets, {n: state.rig.camera(n).device for n in state.names})
    except (OSError, OutputError, DiskFullError) as exc:  # rigctl.publish says a failed write in one line
        state.notes.append(f"{sidecars.NOT_WRITTEN}: {getattr(exc, 'strerror', None) or exc}")
        extras_failed = True
    if truth is not None:
        if disk_full:
            state.notes.append("ground truth not written: the destination is full")
            extras_failed = True
        else:
            # a slot every camera missed has nothing to have truth for
            members = [
                (s.number, {c: state.stats[c].written[i][0] for c, i in s.members.items()}) for s in sets if s.members
            ]
            try:
                truth.write_truth(folder / "truth", members)
            except (OSError, OutputError, DiskFullError) as exc:
                state.notes.append(f"ground truth not written: {getattr(exc, 'strerror', None) or exc}")
                extras_failed = True
    manifest = take_manifest(state, status, sets, end, rectification)
    if extras_failed:
        try:
            write_manifest(folder, manifest)
        except OSError:
            log.warning("%s: notes could not be added to the manifest", folder)
    return manifest
