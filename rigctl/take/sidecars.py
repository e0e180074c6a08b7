"""Sidecar logs of a take: frame sets and per-camera summaries as CSV, and an Avid ALE for editorial."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from rigctl.interfaces import CaptureFormat
from rigctl.publish import publish_text
from rigctl.take.accounting import CameraStats
from rigctl.take.framesets import FrameSet
from rigctl.timecode import Timecode, start_timecode

# how the recorder's note begins when it could not write them (``take.build.finalise``): ``take check`` then
# does not warn of them missing (``sidecar_check.missing_sidecars``)
NOT_WRITTEN = "sidecar logs not written"


def set_timecode(s: FrameSet, start: Timecode) -> Timecode:
    """A frame set's timecode: its own when it was assembled by timecode, else the take's start plus its number."""
    return Timecode(0, start.rate, start.drop) + s.timecode if s.timecode is not None else start + s.number


def write_sets_csv(
    path: Path, sets: list[FrameSet], cameras: list[str], stats: dict[str, CameraStats], start: Timecode
) -> None:
    """One row per frame set: number, timecode, time, complete, spread, and each camera's sequence number
    (blank: missing)."""
    f = io.StringIO(newline="")
    w = csv.writer(f)
    w.writerow(["set", "timecode", "time_ns", "complete", "spread_us", *cameras])
    for s in sets:
        seqs = [stats[c].written[s.members[c]][0] if c in s.members else "" for c in cameras]
        tc = str(set_timecode(s, start))
        w.writerow([s.number, tc, s.time_ns, int(s.complete(cameras)), round(s.spread_ns / 1e3, 1), *seqs])
    publish_text(path, f.getvalue())  # whole at its name or absent: a take can end in a kill or a full disk


def write_log_csv(path: Path, names: list[str], devices: dict[str, str], stats: dict[str, CameraStats]) -> None:
    """One row per camera: what it delivered and what was lost where."""
    f = io.StringIO(newline="")
    w = csv.writer(f)
    w.writerow(
        [
            "camera",
            "device",
            "frames",
            "first_sequence",
            "last_sequence",
            "source_drops",
            "error_frames",
            "writer_drops",
            "not_written",
            "bytes",
            "ended_early",
        ]
    )
    for name in names:
        st = stats[name]
        device = devices[name]
        first = st.written[0][0] if st.written else ""
        last = st.written[-1][0] if st.written else ""
        w.writerow(
            [
                name,
                device,
                st.frames_written,
                first,
                last,
                len(st.source_drops),
                len(st.error_frames),
                len(st.writer_drops),
                len(st.not_written),
                st.bytes_written,
                st.ended,
            ]
        )
    publish_text(path, f.getvalue())


def write_ale(
    path: Path, take: str, started_utc: str, fmt: CaptureFormat, names: list[str], stats: dict[str, CameraStats]
) -> None:
    """Avid Log Exchange: one clip per camera, named TAKE_CAMERA, with start and end (exclusive) timecode:
    the camera's own timecode when its frames carry one, else the take's time-of-day start."""
    take_start = start_timecode(started_utc, fmt.fps)
    fps = fmt.fps
    header = [
        "Heading",
        "FIELD_DELIM\tTABS",
        f"VIDEO_FORMAT\t{fmt.height}p",
        f"FPS\t{fps:g}",
        "",
        "Column",
        "\t".join(["Name", "Tracks", "Start", "End", "Tape", "Camera", "Frames", "Drops"]),
        "",
        "Data",
    ]
    rows: list[Any] = []
    for name in names:
        st = stats[name]
        n = st.frames_written
        span = st.written[-1][0] - st.written[0][0] + 1 if st.written else 0  # frames the clip spans
        start = st.first_timecode if st.first_timecode is not None else take_start
        end = start + span
        drops = len(st.source_drops) + len(st.writer_drops) + len(st.error_frames) + len(st.not_written)
        rows.append("\t".join([f"{take}_{name}", "V", str(start), str(end), take, name, str(n), str(drops)]))
    publish_text(path, "\n".join(header + rows) + "\n")
