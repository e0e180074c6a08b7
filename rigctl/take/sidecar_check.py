"""``rigctl take check`` of the per-camera sidecars editorial reads (``sidecars.py``): ``log.csv`` (what each
camera delivered and lost) and the Avid ALE ``TAKE.ale`` (one clip per camera). Nothing of rigctl reads them
back, so a hand edit, another tool's rewrite or a copy from another take went unnoticed while ``take check``
said ok. Each is held to ``take.yaml`` and the indexes; the first problem is one line naming the file, the
line and the field. An absent sidecar is a warning (:func:`missing_sidecars`) only where the recorder wrote
it: a rectified take, one whose recording did not end, or one whose manifest notes that they could not be
written has none."""

from __future__ import annotations

import contextlib
import csv
import io
import os
import re
from pathlib import Path

from rigctl.errors import ParameterError, RigctlError, TakeError
from rigctl.regular import read_regular
from rigctl.take.names import check_take_name
from rigctl.take.reader import TakeReader
from rigctl.take.sidecars import NOT_WRITTEN
from rigctl.timecode import Timecode, TimecodeError, rate_of, start_timecode

LOG_COLUMNS = [
    *("camera", "device", "frames", "first_sequence", "last_sequence"),
    *("source_drops", "error_frames", "writer_drops", "not_written", "bytes", "ended_early"),
]
ALE_COLUMNS = ["Name", "Tracks", "Start", "End", "Tape", "Camera", "Frames", "Drops"]
ROW_BYTES = 4096  # a sidecar's row at the most (a device path, a reason the stream ended); the header's as many


def _text(path: Path, cameras: int, what: str) -> str:
    data = read_regular(path, ROW_BYTES * (cameras + 12), TakeError, what)
    try:
        return data.decode()
    except UnicodeDecodeError as exc:
        raise TakeError(f"{path}: byte {exc.start}: {what} is not UTF-8 text") from None


def _expected(reader: TakeReader, name: str) -> dict[str, str]:
    """What ``log.csv`` says of camera ``name`` when it holds to take.yaml and the index."""
    entry = reader.manifest.cameras[name]
    first, last = entry.first_sequence, entry.last_sequence
    return {
        "frames": str(entry.frames),
        "first_sequence": "" if first is None else str(first),
        "last_sequence": "" if last is None else str(last),
        "source_drops": str(len(entry.source_drops)),
        "error_frames": str(len(entry.error_frames)),
        "writer_drops": str(len(entry.writer_drops)),
        "not_written": str(len(entry.not_written)),
        "bytes": str(int(reader.index[name]["size"].sum())),
        "ended_early": entry.ended_early or "",
    }


def missing_sidecars(reader: TakeReader) -> list[str]:
    """The sidecars the recorder writes at a take's end (``sets.csv`` as ``frame_sets.file`` names it,
    ``log.csv``, ``TAKE.ale``) that a take which ended is missing, a warning each: the frames are all there,
    but editorial's lists were lost (a copy that left them behind, a hand clean-up). None is looked for in a take
    still ``recording``, a rectified one (``rectification.source_take``: ``rigctl rectify`` writes none) or one
    whose notes say they could not be written (the recorder said why then); ``sets.csv`` not in one without
    frame sets."""
    man = reader.manifest
    rectified = man.rectification is not None and man.rectification.source_take is not None
    noted = any(n.startswith(NOT_WRITTEN) for n in man.notes)
    if man.status == "recording" or rectified or noted:
        return []
    # without frame sets (a take.yaml from elsewhere, or edited) there is no sets.csv to look for; the camera
    # log and the ALE are the recorder's all the same
    names = ([man.frame_sets.file] if man.frame_sets is not None else []) + ["log.csv"]
    with contextlib.suppress(ParameterError):  # a take name that is no plain file name: rigctl wrote no ALE of it
        names.append(f"{check_take_name(man.take)}.ale")
    return [  # once each (frame_sets.file may name log.csv or the ALE)
        f"{reader.folder / n}: missing; the recorder writes it when a take ends (its frames are not affected: "
        "nothing of rigctl reads it back, editorial does)"
        for n in dict.fromkeys(names)
        if not os.path.lexists(reader.folder / n)
    ]


def log_problem(reader: TakeReader) -> str | None:
    """``log.csv`` against the take: its header, one row per camera of take.yaml in order, and each row's
    frames, sequence numbers, losses, bytes (the index's frames) and why the stream ended as take.yaml has them."""
    path = reader.folder / "log.csv"
    if not os.path.lexists(path):
        return None
    names = reader.names
    try:
        parse = csv.reader(io.StringIO(_text(path, len(names), "camera log"), newline=""))
        numbered = [(parse.line_num, row) for row in parse if row]  # each record's last line; blank lines skipped
    except RigctlError as exc:
        return str(exc)
    except csv.Error as exc:
        return f"{path}: line {parse.line_num}: {exc}"
    rows = [row for _, row in numbered]
    if not rows or rows[0] != LOG_COLUMNS:
        got = ",".join(rows[0]) if rows else ""
        return f"{path}: line 1: header {got!r:.100} is not {','.join(LOG_COLUMNS)!r:.100}"
    for (line, row), name in zip(numbered[1:], names, strict=False):
        if len(row) != len(LOG_COLUMNS):
            return f"{path}: line {line}: {len(row)} fields, the header has {len(LOG_COLUMNS)}"
        if row[0] != name:
            return f"{path}: line {line}: camera {row[0]!r:.40} is not {name} (take.yaml's cameras, in order)"
        for column, want in _expected(reader, name).items():
            got = row[LOG_COLUMNS.index(column)]
            if got != want:
                return f"{path}: line {line}: {name} {column} {got!r:.40}, take.yaml and the index say {want!r:.40}"
    if len(rows) - 1 != len(names):
        return f"{path}: {len(rows) - 1} camera rows, take.yaml has {len(names)} cameras"
    return None


def ale_problem(reader: TakeReader) -> str | None:
    """``TAKE.ale`` against the take: tab-delimited, the take's frame rate, its columns, one clip per camera of
    take.yaml in order named TAKE_CAMERA on tape TAKE, timecodes at the take's rate spanning the camera's
    sequence numbers, its frames and its losses."""
    man = reader.manifest
    try:
        take = check_take_name(man.take)
    except ParameterError:
        return None  # a name that is no plain file name: no ALE of it is looked for (nor written by rigctl)
    path = reader.folder / f"{take}.ale"
    if not os.path.lexists(path):
        return None
    try:
        lines = re.split(r"\r?\n", _text(path, len(reader.names), "ALE"))  # other tools write CRLF
    except RigctlError as exc:
        return str(exc)
    rate, _ = rate_of(man.format.fps)
    heading = {"FIELD_DELIM": "TABS", "FPS": f"{man.format.fps:g}"}
    try:
        column, data = lines.index("Column"), lines.index("Data")
    except ValueError:
        return f"{path}: no 'Column' and 'Data' lines: not an ALE"
    for key, want in heading.items():
        got = next((ln.split("\t", 1)[1] for ln in lines[:column] if ln.startswith(f"{key}\t")), None)
        if got != want:
            return f"{path}: {key} {got!r:.40}, the take's is {want!r}"
    if column + 1 >= len(lines) or lines[column + 1].split("\t") != ALE_COLUMNS:
        return f"{path}: line {column + 2}: columns are not {' '.join(ALE_COLUMNS)!r}"
    rows = [(i, ln) for i, ln in enumerate(lines[data + 1 :], start=data + 2) if ln]
    for (line, text), name in zip(rows, reader.names, strict=False):
        problem = _clip_problem(reader, take, name, text.split("\t"), rate)
        if problem:
            return f"{path}: line {line}: {problem}"
    if len(rows) != len(reader.names):
        return f"{path}: {len(rows)} clips, take.yaml has {len(reader.names)} cameras"
    return None


def _clip_problem(reader: TakeReader, take: str, name: str, row: list[str], rate: int) -> str | None:
    if len(row) != len(ALE_COLUMNS):
        return f"{len(row)} fields, the columns are {len(ALE_COLUMNS)}"
    entry = reader.manifest.cameras[name]
    lost = len(entry.source_drops) + len(entry.writer_drops) + len(entry.error_frames) + len(entry.not_written)
    fixed = {"Name": f"{take}_{name}", "Tracks": "V", "Tape": take, "Camera": name}
    fixed |= {"Frames": str(entry.frames), "Drops": str(lost)}
    for column, want in fixed.items():
        got = row[ALE_COLUMNS.index(column)]
        if got != want:
            return f"{name} {column} {got!r:.40}, take.yaml says {want!r:.40}"
    first_label = _clip_start(reader, name)
    label = row[ALE_COLUMNS.index("Start")]
    if first_label is not None and label != first_label:
        return f"{name} Start {label!r:.40}, its first frame's timecode (or the take's start) is {first_label}"
    try:
        # drop-frame or not as written (the camera's own timecode, whatever the rate's custom)
        start, end = (Timecode.parse(row[ALE_COLUMNS.index(c)], rate) for c in ("Start", "End"))
        frames = end - start
    except TimecodeError as exc:
        return f"{name}: {exc}"
    first, last = entry.first_sequence, entry.last_sequence
    span = last - first + 1 if first is not None and last is not None else 0
    if frames != span:
        return f"{name} Start {start} to End {end} spans {frames} frames, its sequence numbers {span}"
    return None


def _clip_start(reader: TakeReader, name: str) -> str | None:
    """The clip's Start as the recorder writes it: the camera's first frame's timecode when its frames carry one,
    else the take's time-of-day start; None when neither can be told (a damaged index or start time)."""
    try:
        own = reader.timecode(name, 0) if len(reader.index[name]) else None
        return str(own if own is not None else start_timecode(reader.manifest.started_utc, reader.manifest.format.fps))
    except RigctlError:
        return None
