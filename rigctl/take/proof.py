"""What a take must prove before any reader trusts it, beyond each frame's checksum (``take check`` lists
every problem; :class:`~rigctl.take.reader.TakeReader` refuses on the first):

- the format is one rigctl reads, within a pixel budget, and agrees with the rig snapshot the manifest holds
  (or, for a rectified take, with its rectification's image size);
- the frame period agrees with the rate;
- each camera's records lie in its own essence file, in the order they were written, none overlapping
  another, each of the format's size;
- each camera's records lie between the manifest's first and last sequence numbers for it (are its first and
  last, in a finished take whose frames are all there);
- each camera's records name that camera (index version 2): two cameras' files swapped or renamed are caught
  though every checksum holds;
- each camera's capture times increase, never three frames within one frame period (one late timestamp
  is allowed), and all cameras' times together span no more than their frames can (a hostile time would ask
  for billions of frame sets).

Problems name the file and byte offset. A CRC protects each record from damage, not from a lie: a record
rewritten with a valid CRC is caught here.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rigctl.rig import MAX_FRAME_PIXELS
from rigctl.take.index import RECORD_SIZE, camera_tag
from rigctl.take.manifest import CameraEntry, Manifest

MAX_PIXELS = MAX_FRAME_PIXELS  # 134 million pixels a frame (16384 x 8192): beyond it a manifest is lying
SPAN_SLACK_FRAMES = 1000


def format_problems(manifest: Manifest, manifest_path: Path) -> list[str]:
    """The format against the pixel budget, the rate and the rig snapshot."""
    fmt = manifest.format
    out = []
    if fmt.width * fmt.height > MAX_PIXELS:
        out.append(
            f"{manifest_path}: format {fmt.width}x{fmt.height} is over the budget of {MAX_PIXELS:,} pixels a frame"
        )
    nominal = 1e9 / fmt.fps
    period = manifest.timing.frame_period_ns
    if period is not None and not nominal / 2 <= period <= nominal * 2:
        out.append(
            f"{manifest_path}: timing.frame_period_ns {period} does not agree with format.fps {fmt.fps:g} "
            f"({nominal:.0f} ns a frame)"
        )
    if manifest.rectification is not None:
        size = list(manifest.rectification.image_size)
        if size != [fmt.width, fmt.height]:
            out.append(f"{manifest_path}: format {fmt.width}x{fmt.height} differs from rectification.image_size {size}")
        return out
    rig_format = manifest.rig.get("format") if isinstance(manifest.rig, Mapping) else None
    if isinstance(rig_format, Mapping):
        expect = (rig_format.get("width_px"), rig_format.get("height_px"))
        if all(isinstance(v, int) for v in expect) and expect != (fmt.width, fmt.height):
            out.append(
                f"{manifest_path}: format {fmt.width}x{fmt.height} differs from the rig snapshot's "
                f"{expect[0]}x{expect[1]} (rig.format)"
            )
    return out


def record_problems(ipath: Path, idx: NDArray[np.void], bytes_per_frame: int, period_ns: int) -> list[str]:
    """One camera's records: sizes, order and overlap in the essence file, capture times."""
    out: list[str] = []
    if len(idx) == 0:
        return out
    size = idx["size"].astype(np.int64)
    wrong = np.flatnonzero(size != bytes_per_frame)
    if wrong.size:
        k = int(wrong[0])
        out.append(f"{ipath}: byte {k * RECORD_SIZE}: frame of {int(size[k])} bytes, format needs {bytes_per_frame}")
    off = idx["offset"].astype(np.int64)
    overlap = np.flatnonzero(off[1:] < off[:-1] + size[:-1])
    if overlap.size:
        k = int(overlap[0]) + 1
        out.append(
            f"{ipath}: byte {k * RECORD_SIZE}: frame at essence offset {int(off[k])} lies inside or before the frame "
            f"recorded before it (offset {int(off[k - 1])}, {int(size[k - 1])} bytes)"
        )
    seq = idx["sequence"].astype(np.int64)
    if np.any(np.diff(seq) <= 0):
        k = int(np.flatnonzero(np.diff(seq) <= 0)[0]) + 1
        out.append(f"{ipath}: byte {k * RECORD_SIZE}: sequence {seq[k]} does not follow {seq[k - 1]}")
    cap = idx["capture_ns"].astype(np.int64)
    step = np.diff(cap)
    if np.any(step <= 0):
        k = int(np.flatnonzero(step <= 0)[0]) + 1
        out.append(f"{ipath}: byte {k * RECORD_SIZE}: capture time goes backwards")
    elif len(step) >= 2 and np.any(step[1:] + step[:-1] < period_ns):
        # three frames within one period: faster than the rate, however a frame's time may be late. One short
        # step alone is not: a driver starved of CPU stamps a late frame late and the next on time (seen on
        # the kernel's vivid devices under load, 17 ms after a late frame at 25 fps), and refusing the take
        # for it would lose a whole recording to one timestamp
        k = int(np.flatnonzero(step[1:] + step[:-1] < period_ns)[0]) + 2
        out.append(
            f"{ipath}: byte {k * RECORD_SIZE}: capture time {int(step[k - 2] + step[k - 1])} ns after the frame two "
            f"before, faster than the rate allows ({period_ns} ns a frame)"
        )
    return out


def sequence_problems(
    mpath: Path, name: str, entry: CameraEntry, ipath: Path, idx: NDArray[np.void], ends: bool
) -> list[str]:
    """The manifest's ``first_sequence`` and ``last_sequence`` of camera ``name`` against its index: every record
    between them, and (``ends``: a finished take whose index and frames are whole) the first and last records
    theirs. A take made with ``--skip-damaged`` may lack its source's first or last frame: only ``between``."""
    first, last = entry.first_sequence, entry.last_sequence
    if first is None or last is None or not len(idx):
        return []
    lo, hi = int(idx["sequence"][0]), int(idx["sequence"][-1])  # increasing: record_problems
    if first <= lo and hi <= last and (not ends or (lo, hi) == (first, last)):
        return []
    return [
        f"{mpath}: cameras.{name}.first_sequence {first} and last_sequence {last} disagree with {ipath.name}, "
        f"whose records run from sequence {lo} to {hi}"
    ]


def span_problem(folder: Path, index: Mapping[str, NDArray[np.void]], period_ns: int) -> str | None:
    """All cameras' capture times must fit the frames recorded: frame sets are made one a period over the span."""
    used = [i["capture_ns"].astype(np.int64) for i in index.values() if len(i)]
    if not used:
        return None
    lo, hi = min(int(c.min()) for c in used), max(int(c.max()) for c in used)
    frames = max(len(c) for c in used)
    span = (hi - lo) // max(period_ns, 1) + 1
    if span > 4 * frames + SPAN_SLACK_FRAMES:
        return (
            f"{folder}: the indexes' capture times span {span:,} frame periods for at most {frames:,} frames a "
            "camera: an index is damaged or lies"
        )
    return None


def file_problems(folder: Path, paths: Mapping[str, tuple[Path, Path]]) -> list[str]:
    """No two cameras share an essence or index file."""
    seen: dict[Path, str] = {}
    out = []
    for name, files in paths.items():
        for p in files:
            real = p.resolve()
            if real in seen:
                out.append(f"{folder / 'take.yaml'}: cameras.{name}: {p} is also camera {seen[real]}'s file")
            seen[real] = name
    return out


def identity_problems(ipath: Path, idx: NDArray[np.void], name: str, names: list[str]) -> list[str]:
    """Camera ``name``'s records must name ``name``: a record of another camera of the take (files swapped or
    renamed), of no camera of it, or a version 1 record among version 2 ones is a lie."""
    if len(idx) == 0:
        return []
    version = idx["version"].astype(np.int64)
    if np.all(version == 1):
        return []  # an older take: its records name no camera (see :func:`unproven_identity`)
    old = np.flatnonzero(version == 1)
    if old.size:
        k = int(old[0])
        return [f"{ipath}: byte {k * RECORD_SIZE}: a version 1 record (no camera) among version 2 records"]
    tags = idx["camera"].astype(np.int64)
    wrong = np.flatnonzero(tags != camera_tag(name))
    if not wrong.size:
        return []
    k = int(wrong[0])
    owner = next((n for n in names if camera_tag(n) == int(tags[k])), None)
    whose = f"camera {owner}'s" if owner else "a camera not in this take"
    return [
        f"{ipath}: byte {k * RECORD_SIZE}: record of {whose} frame in camera {name}'s index: the cameras' files "
        "are swapped or renamed"
    ]


def unproven_identity(folder: Path, index: Mapping[str, NDArray[np.void]]) -> str | None:
    """The notice for a take whose records name no camera (written before index version 2)."""
    old = [n for n, i in index.items() if len(i) and np.all(i["version"] == 1)]
    if not old:
        return None
    return (
        f"{folder}: index records of {', '.join(old)} name no camera (written by a rigctl before index version 2): "
        "two cameras' files swapped on disk cannot be detected in this take"
    )
