"""Sidecar logs of a take: frame sets and per-camera summaries as CSV, and an Avid ALE for editorial."""

from __future__ import annotations

import csv
import datetime as dt
from pathlib import Path
from typing import Any

from rigctl.interfaces import CaptureFormat
from rigctl.take.accounting import CameraStats
from rigctl.take.framesets import FrameSet


def timecode_of(iso_utc: str, fps: float, frames_after: int = 0) -> str:
    """Time-of-day timecode (UTC) of an ISO time plus some frames; drop-frame (';') at 29.97/59.94."""
    if not iso_utc:
        return "00:00:00:00"
    t = dt.datetime.fromisoformat(iso_utc)
    nominal = round(fps)
    seconds = t.hour * 3600 + t.minute * 60 + t.second + t.microsecond / 1e6
    total = int(seconds * nominal) + frames_after
    ff = total % nominal
    s = total // nominal
    sep = ";" if abs(fps - nominal * 1000 / 1001) < 1e-3 else ":"
    return f"{s // 3600 % 24:02d}:{s // 60 % 60:02d}:{s % 60:02d}{sep}{ff:02d}"


def write_sets_csv(path: Path, sets: list[FrameSet], cameras: list[str], stats: dict[str, CameraStats]) -> None:
    """One row per frame set: number, time, complete, spread, and each camera's sequence number (blank:
    missing)."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["set", "time_ns", "complete", "spread_us", *cameras])
        for s in sets:
            seqs = [stats[c].written[s.members[c]][0] if c in s.members else "" for c in cameras]
            w.writerow([s.number, s.time_ns, int(s.complete(cameras)), round(s.spread_ns / 1e3, 1), *seqs])


def write_log_csv(path: Path, names: list[str], devices: dict[str, str], stats: dict[str, CameraStats]) -> None:
    """One row per camera: what it delivered and what was lost where."""
    with open(path, "w", newline="") as f:
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


def write_ale(
    path: Path, take: str, started_utc: str, fmt: CaptureFormat, names: list[str], stats: dict[str, CameraStats]
) -> None:
    """Avid Log Exchange: one clip per camera, named TAKE_CAMERA, with start and end timecode."""
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
        start = timecode_of(started_utc, fps)
        end = timecode_of(started_utc, fps, frames_after=span)
        drops = len(st.source_drops) + len(st.writer_drops) + len(st.error_frames) + len(st.not_written)
        rows.append("\t".join([f"{take}_{name}", "V", start, end, take, name, str(n), str(drops)]))
    path.write_text("\n".join(header + rows) + "\n")
