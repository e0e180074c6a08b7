"""``rigctl take check``: is everything the take claims readable? Problems name file and byte offset."""

from __future__ import annotations

import os
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from rigctl.errors import RigctlError, TakeError
from rigctl.regular import open_regular
from rigctl.take.reader import TakeReader


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
