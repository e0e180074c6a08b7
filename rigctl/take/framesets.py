"""Frame sets: which frames of the cameras were captured together, assembled by time.

Genlock makes the sensors scan together but does not tell the host which captured frames belong
together (sequence numbers restart on every start, cameras start at different moments). Frames are
therefore grouped by capture timestamp, within half a frame period of each set's time (one frame stamped up to a
period late or early still finds its own set when its neighbour is on time), tracking the
rig's phase; or by timecode (its frame count, exact at drop-frame rates) when every frame carries one.
A camera missing from a set leaves an explicit gap: later sets are never shifted.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import ParameterError
from rigctl.interfaces import FrameFlags
from rigctl.timecode import Timecode, TimecodeError, rate_of, unwrap


@dataclass(frozen=True)
class FrameSet:
    """One instant of the take: set number, time (ns), and per camera the position in its index."""

    number: int
    time_ns: int
    members: dict[str, int]
    spread_ns: int
    timecode: int | None = None  # frames since midnight (unwrapped past it) when assembled by timecode

    def complete(self, cameras: list[str]) -> bool:
        return all(c in self.members for c in cameras)


def assemble(
    timestamps: dict[str, NDArray[np.int64]],
    period_ns: int,
    t0_ns: int | None = None,
    timecodes: dict[str, NDArray[np.int64]] | None = None,
) -> list[FrameSet]:
    """Group per-camera capture timestamps (each sorted, in ns) into frame sets.

    With ``timecodes`` (frame counts, one per frame, for every camera) sets are formed by equal
    timecode. Otherwise each set collects, per camera, the frame within half a period of the set's
    expected time; the expected time follows the median of each set's members, so a slow drift of the
    rig's clock against the host's is tracked. ``t0_ns`` is the recording start: set 0 is the first
    frame slot at or after it.
    """
    if timecodes is not None:
        return _by_timecode(timestamps, timecodes)
    items = [(int(t), cam, i) for cam, ts in timestamps.items() for i, t in enumerate(ts)]
    if not items:
        return []
    items.sort()
    half = period_ns // 2
    first = [int(ts[0]) for ts in timestamps.values() if len(ts)]
    if t0_ns is not None:
        in_slot = [t for t in first if t0_ns <= t < t0_ns + period_ns]
        expected = int(np.median(in_slot)) if in_slot else min(first)
    else:
        expected = int(np.median([t for t in first if t < min(first) + half])) if first else items[0][0]
    sets: list[FrameSet] = []
    k = 0
    number = 0
    carried: dict[str, tuple[int, int]] = {}  # a camera's frame stamped early, for the next set
    while k < len(items) or carried:
        lo, hi = expected - half, expected + half
        members = {cam: i for cam, (_, i) in carried.items()}
        stamps = {cam: t for cam, (t, _) in carried.items()}
        carried = {}
        while k < len(items) and items[k][0] < hi:
            t, cam, i = items[k]
            k += 1
            if t < lo:
                continue  # before the window: only timestamps that jump back do that; left out
            if cam not in members:
                members[cam], stamps[cam] = i, t
                continue
            # a second frame of the camera within half a period: one of the two was stamped more than half
            # a period off its slot (a host starved of CPU stamps a frame late; the next one on time). The
            # earlier goes back to the set before when that set lacks the camera and it is less than a period
            # late for it; else the later goes on to the next set when it lies past this one's time; else
            # (two frames at one instant) the later is left out. Nothing is shifted past one slot.
            prev = sets[-1] if sets and sets[-1].number == number - 1 else None
            if prev is not None and cam not in prev.members and 0 <= stamps[cam] - prev.time_ns < period_ns:
                sets[-1] = _with_member(prev, cam, members[cam], stamps[cam], timestamps)
                members[cam], stamps[cam] = i, t
            elif t > expected:
                carried[cam] = (t, i)
        times = list(stamps.values())
        if times:
            centre = int(np.median(times))
            sets.append(FrameSet(number, centre, members, max(times) - min(times)))
            expected = expected + period_ns + (centre - expected) // 2
        else:
            sets.append(FrameSet(number, expected, {}, 0))
            expected += period_ns
        number += 1
    while sets and not sets[-1].members:
        sets.pop()
    return sets


def _with_member(fs: FrameSet, cam: str, index: int, t: int, timestamps: dict[str, NDArray[np.int64]]) -> FrameSet:
    """``fs`` with ``cam``'s frame ``index`` (stamped ``t``) added: its time stays that of the others (the
    tracked phase), its spread counts the added stamp."""
    times = [int(timestamps[c][i]) for c, i in fs.members.items()] + [t]
    return FrameSet(fs.number, fs.time_ns, {**fs.members, cam: index}, max(times) - min(times), fs.timecode)


def timecode_counts(indexes: dict[str, NDArray[np.void]], fps: float) -> dict[str, NDArray[np.int64]] | None:
    """Per camera, the timecode counts of its index records (unwrapped past midnight) when every frame of
    every camera carries one; else None (sets are then assembled by time)."""
    flags = [idx["flags"] for idx in indexes.values() if len(idx)]
    if not flags or not all(np.all(f & FrameFlags.TIMECODE) for f in flags):
        return None
    # one rate and drop flag for the whole take, else counts of different scales would be compared
    drops = {bool(v) for f in flags for v in np.unique(f & FrameFlags.DROP_FRAME)}
    if len(drops) > 1:
        raise TimecodeError("some frames count drop-frame timecode and some do not")
    rate, _ = rate_of(fps)
    drop = drops.pop()
    Timecode(0, rate, drop)  # refuses drop-frame at a rate that has none
    first = min(int(idx["timecode"][0]) for idx in indexes.values() if len(idx))
    return {n: unwrap(idx["timecode"], first, rate, drop) for n, idx in indexes.items()}


def _by_timecode(timestamps: dict[str, NDArray[np.int64]], timecodes: dict[str, NDArray[np.int64]]) -> list[FrameSet]:
    start = min(int(tc[0]) for tc in timecodes.values() if len(tc))
    end = max(int(tc[-1]) for tc in timecodes.values() if len(tc))
    slots: list[dict[str, int]] = [{} for _ in range(end - start + 1)]
    for cam, tcs in timecodes.items():
        for i, tc in enumerate(tcs):
            slots[int(tc) - start].setdefault(cam, i)
    out = []
    for n, members in enumerate(slots):
        times = [int(timestamps[c][i]) for c, i in members.items()]
        t = int(np.median(times)) if times else 0
        out.append(FrameSet(n, t, members, (max(times) - min(times)) if times else 0, start + n))
    return out


def skew_stats(sets: list[FrameSet]) -> dict[str, float]:
    """Spread of capture times within frame sets of two or more cameras: p50, p99 and max, in us."""
    spreads = np.array([s.spread_ns for s in sets if len(s.members) > 1], dtype=np.float64) / 1e3
    if spreads.size == 0:
        return {"p50_us": 0.0, "p99_us": 0.0, "max_us": 0.0, "sets": 0}
    return {
        "p50_us": round(float(np.percentile(spreads, 50)), 1),
        "p99_us": round(float(np.percentile(spreads, 99)), 1),
        "max_us": round(float(spreads.max()), 1),
        "sets": int(spreads.size),
    }


FRAMES = re.compile(r"([0-9]+)(?:-([0-9]+))?")


def parse_frames(text: str) -> range:
    """``--frames`` of every verb that takes it: ``N`` or ``A-B`` (inclusive, frame-set numbers from 0) as a
    range. Only its form is checked here; :func:`check_frames` checks it against what the input holds."""
    m = FRAMES.fullmatch(text.strip())
    if m is None:
        raise ParameterError(f"--frames {text!r}: expected N or A-B, e.g. 0-24")
    a = int(m[1])
    b = a if m[2] is None else int(m[2])
    if b < a:
        raise ParameterError(f"--frames {text!r}: need 0 <= A <= B")
    return range(a, b + 1)


def check_frames(
    frames: Sequence[int] | None, numbers: Sequence[int], source: object, kind: str = "complete frame set"
) -> list[int]:
    """The frame sets ``frames`` (--frames, :func:`parse_frames`) asks for, each one of ``numbers`` (what
    ``source`` holds: its complete frame sets, say), else one line naming --frames and what ``source`` has
    (exit 2): a range past the end is refused, never shrunk to fit. ``None``, --frames not given: every one of
    ``numbers``."""
    if frames is None:
        return list(numbers)
    # a range is never walked nor measured with len(): --frames 0-99999999999999999999 is quick, one line
    wanted = frames if isinstance(frames, range) else set(frames)
    size = frames.stop - frames.start if isinstance(frames, range) else len(wanted)
    present = {n for n in numbers if n in wanted}
    if len(present) == size:
        return list(frames)
    first = next(f for f in frames if f not in present)  # within the first len(present) + 1 of them
    if isinstance(frames, range):
        last = frames.stop - 1
        asked = f"{frames.start}" if last == frames.start else f"{frames.start}-{last}"
    else:
        asked = ranges(sorted(wanted))
    has = f"its {kind}s: {ranges(sorted(numbers))}" if numbers else f"it has no {kind}"
    raise ParameterError(f"--frames {asked}: {source} has no {kind} {first} ({has})")


def ranges(numbers: Sequence[int]) -> str:
    """1, 2, 3, 7 -> '1-3, 7'."""
    out: list[str] = []
    if not numbers:
        return ""
    start = prev = numbers[0]
    for n in [*numbers[1:], None]:
        if n is not None and n == prev + 1:
            prev = n
            continue
        out.append(f"{start}" if start == prev else f"{start}-{prev}")
        if n is not None:
            start = prev = n
    return ", ".join(out)
