"""``rigctl take check``: is everything the take claims readable? Problems name file and byte offset."""

from __future__ import annotations

import csv
import io
import math
import os
import re
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from rigctl.errors import RigctlError, TakeError
from rigctl.regular import open_regular, read_regular
from rigctl.take.manifest import FrameSetSummary
from rigctl.take.proof import SPAN_SLACK_FRAMES
from rigctl.take.reader import TakeReader
from rigctl.take.sidecar_check import ale_problem, log_problem, missing_sidecars
from rigctl.timecode import Timecode, TimecodeError, rate_of

SETS_COLUMNS = ["set", "timecode", "time_ns", "complete", "spread_us"]  # then one column a camera
SETS_ROW_BYTES = 128  # the fixed columns of a row of sets.csv at the most; each camera's adds 21 (20 digits, a comma)
WHOLE = re.compile(r"-?(0|[1-9][0-9]{0,19})")  # a whole number as rigctl writes one: ASCII, no leading zeros


@dataclass
class CheckReport:
    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    frames_checked: int = 0

    @property
    def ok(self) -> bool:
        return not self.errors


def check_take(folder: Path, verify_data: bool = True) -> CheckReport:
    report = CheckReport()
    try:
        # every problem is listed below, not only the first
        reader = TakeReader(folder, skip_damaged=True, prove=False)
    except RigctlError as exc:
        report.errors.append(str(exc))
        return report
    man = reader.manifest
    report.errors += reader.proof  # what the take fails to prove (rigctl.take.proof)
    report.warnings += [reader.notice] if reader.notice else []
    if not any(len(i) for i in reader.index.values()):
        report.errors.append(f"{folder}: the take holds no readable frame")
    if man.status == "recording":
        report.warnings.append(
            f"{folder / 'take.yaml'}: status 'recording': the recording did not end cleanly (crash or power loss); "
            "what the indexes hold is checked"
        )
    left_out = man.damaged_skipped
    if left_out:
        report.warnings.append(
            f"{folder / 'take.yaml'}: damaged_skipped: {len(left_out)} damaged source frame(s) were left out when "
            "this take was made"
        )
    sidecars = (sets_problem(reader), log_problem(reader), ale_problem(reader))
    report.errors += [p for p in sidecars if p]
    report.warnings += missing_sidecars(reader)
    for name in reader.names:
        idx = reader.index[name]
        ipath = reader.index_path(name)
        epath = reader.essence_path(name)
        for p in reader.problems[name]:
            if p.torn_tail:
                report.warnings.append(f"{p} (torn by the interruption: last frame excluded)")
            else:
                report.errors.append(str(p))
        if epath.stat().st_size == 0 and man.cameras[name].frames:
            report.errors.append(
                f"{epath}: byte 0: essence file of camera {name} is empty, {man.cameras[name].frames} frames claimed"
            )
        entry = man.cameras[name]
        if man.status != "recording" and entry.frames != len(idx):
            report.errors.append(
                f"{folder / 'take.yaml'}: cameras.{name}.frames claims {entry.frames} frames, {ipath.name} holds "
                f"{len(idx)} readable"
            )
        if verify_data and len(idx):
            fd = open_regular(epath, TakeError, f"essence file of camera {name}")[0]
            try:
                for rec in idx:
                    report.frames_checked += 1
                    if not rec["crc"]:
                        continue
                    data = os.pread(fd, int(rec["size"]), int(rec["offset"]))
                    if zlib.crc32(data) != int(rec["crc"]):
                        report.errors.append(
                            f"{epath}: byte {int(rec['offset'])}: frame {int(rec['sequence'])} fails its checksum "
                            f"({int(rec['size'])} bytes from there)"
                        )
            finally:
                os.close(fd)
    return report


def sets_problem(reader: TakeReader) -> str | None:
    """``sets.csv`` (``frame_sets.file``) against the take, or None when it holds (or is not there: a crashed or a
    rectified take has none). Nothing of rigctl reads it back (readers assemble frame sets from the indexes), but
    editorial and other tools do, so what it claims is checked: the manifest's cameras in order in the header, a
    row for every frame set of ``frame_sets.count`` numbered 0, 1, ..., a timecode, whole numbers where they are,
    each camera's sequence number one of its index's and used once, in order, ``complete`` 1 exactly where every
    camera has a frame and the incomplete sets those ``frame_sets.incomplete`` lists. The first problem, naming
    the line, the column and the value (a hostile file of a million rows is one line, not a million)."""
    summary = reader.manifest.frame_sets
    path = reader.folder / summary.file if summary is not None else None
    if summary is None or path is None or not os.path.lexists(path):
        return None
    names = reader.names
    # frame sets are made one a period over the capture times, which span at most this many (rigctl.take.proof)
    most = 4 * max((len(i) for i in reader.index.values()), default=0) + SPAN_SLACK_FRAMES + 1
    try:
        text = read_regular(path, most * (SETS_ROW_BYTES + 21 * len(names)), TakeError, "frame-set file").decode()
    except RigctlError as exc:
        return str(exc)
    except UnicodeDecodeError as exc:
        return f"{path}: byte {exc.start}: not UTF-8 text"
    rows = csv.reader(io.StringIO(text, newline=""))
    try:
        return _rows_problem(path, rows, reader, summary)
    except csv.Error as exc:  # a field past csv's limit, an unclosed quote
        return f"{path}: line {rows.line_num}: {exc}"


def _rows_problem(path: Path, rows: Iterator[list[str]], reader: TakeReader, summary: FrameSetSummary) -> str | None:
    names = reader.names
    header, want = next(rows, []), [*SETS_COLUMNS, *names]
    if header != want:
        return f"{path}: line 1: header {','.join(header)!r:.100} is not {','.join(want)!r:.100} (take.yaml's cameras)"
    known = {n: set(reader.index[n]["sequence"].tolist()) for n in names}
    last = dict.fromkeys(names, -1)
    listed = {s.number: s.missing for s in summary.incomplete}
    count = 0
    for number, row in enumerate(rows):
        count = number + 1
        problem = _row_problem(row, number, want, reader.fps)
        missing = [n for n, cell in zip(names, row[len(SETS_COLUMNS) :], strict=False) if cell == ""]
        for name, cell in zip(names, row[len(SETS_COLUMNS) :], strict=False):
            if problem or cell == "":
                continue
            seq = int(cell) if WHOLE.fullmatch(cell) else -1
            if seq not in known[name]:
                problem = f"{name} {cell!r:.40} is not a sequence number of {reader.index_path(name).name}"
            elif seq <= last[name]:
                problem = f"{name} {cell}: sequence {seq} after {last[name]} (a frame in two sets, or out of order)"
            last[name] = seq
        if not problem and row[3] != ("0" if missing else "1"):
            problem = f"complete {row[3]!r:.10}, but {len(missing)} camera(s) have no frame in the set"
        if not problem and listed.get(number, []) != missing:
            problem = f"cameras missing {missing}, take.yaml frame_sets.incomplete lists {listed.get(number, [])}"
        if problem:
            return f"{path}: line {number + 2}: {problem}"
    if count != summary.count:
        return f"{path}: {count} frame sets, take.yaml frame_sets.count claims {summary.count}"
    return None


def _row_problem(row: list[str], number: int, want: list[str], fps: float) -> str | None:
    """A row's shape and fixed columns: the field count, its set number, timecode, time and spread."""
    if len(row) != len(want):
        return f"{len(row)} fields, the header has {len(want)}"
    if row[0] != str(number):
        return f"set {row[0]!r:.40} is not {number} (frame sets are numbered 0, 1, ... once each)"
    try:
        Timecode.parse(row[1], rate_of(fps)[0])
    except TimecodeError:
        return f"timecode {row[1]!r:.40} is not a timecode at {fps:g} fps"
    if not WHOLE.fullmatch(row[2]):
        return f"time_ns {row[2]!r:.40} is not a whole number"
    try:
        spread = float(row[4])
    except ValueError:
        spread = math.nan
    if not (math.isfinite(spread) and spread >= 0):
        return f"spread_us {row[4]!r:.40} is not a time (finite, not negative)"
    return None
