"""SMPTE ST 12-1 timecode as one value: frames since midnight, the nominal rate and the drop-frame flag.

Everything in rigctl that handles timecode holds this value (or its integer, in a take's index) and
only turns it into text at the edge: ``HH:MM:SS:FF`` for non-drop, ``HH:MM:SS;FF`` for drop-frame.

*Nominal rate* is the integer rate the labels count in: 24 for 23.976 and 24 fps, 30 for 29.97 and 30,
60 for 59.94 and 60. *Drop-frame* (defined for nominal 30 and 60, ST 12-1 with its 2014 60-frame
extension) skips the labels ``;00`` and ``;01`` (``;00``-``;03`` at 60) at the start of every minute
except minutes 00, 10, 20, 30, 40 and 50, so that the labels of 29.97/59.94 fps video stay within
86 ms a day of the clock. The frame *count* since midnight never skips: two different frames always
have two different counts, which is what frame sets are built on.
"""

from __future__ import annotations

import datetime as dt
import logging
import math
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from rigctl.errors import ParameterError

log = logging.getLogger(__name__)

SMPTE_RATES = (24, 25, 30, 48, 50, 60)  # nominal rates of ST 12-1; other whole rates count the same way
MAX_RATE = 1000
_DROPPED = {30: 2, 60: 4}  # labels dropped per minute (except every tenth) at each drop-frame nominal rate
_TEXT = re.compile(r"^(\d{2}):(\d{2}):(\d{2})([:;.,])(\d{2,3})$")


class TimecodeError(ParameterError):
    """A timecode label or count that does not exist at its rate (e.g. ``00:01:00;00`` at 29.97 DF)."""


def is_fractional(fps: float) -> bool:
    """Is ``fps`` an NTSC-family rate (n * 1000/1001: 23.976, 29.97, 59.94)? Either 29.97 or 30000/1001 is."""
    nominal = round(fps)
    return nominal > 0 and abs(fps - nominal * 1000 / 1001) < 1e-3 and abs(fps - nominal) > 1e-3


def rate_of(fps: float) -> tuple[int, bool]:
    """The nominal rate and customary drop flag for a frame rate: 29.97 and 59.94 count drop-frame, 23.976
    counts 24 non-drop (ST 12-1 defines no drop-frame at 24)."""
    if not (math.isfinite(fps) and 0.5 <= fps <= MAX_RATE):
        raise TimecodeError(f"frame rate {fps!r}: a timecode needs 1..{MAX_RATE} fps")
    nominal = round(fps)
    return nominal, is_fractional(fps) and nominal in _DROPPED


def frames_per_day(rate: int, drop: bool) -> int:
    """Frame counts from 00:00:00:00 up to (not including) 24:00:00:00."""
    if drop:
        d = _DROPPED[rate]
        return 24 * 6 * (rate * 600 - 9 * d)
    return 24 * 3600 * rate


@dataclass(frozen=True, slots=True, order=True)
class Timecode:
    """A timecode: ``frames`` since midnight (0 = ``00:00:00:00``) at nominal ``rate``, ``drop``-frame or not.

    Values of one rate and drop flag compare and subtract as frame counts; ``tc + n`` wraps at midnight.
    """

    frames: int
    rate: int
    drop: bool = False

    def __post_init__(self) -> None:
        if not 1 <= self.rate <= MAX_RATE:
            raise TimecodeError(f"timecode rate {self.rate}: expected 1..{MAX_RATE} (SMPTE: {SMPTE_RATES})")
        if self.drop and self.rate not in _DROPPED:
            raise TimecodeError(f"timecode rate {self.rate}: drop-frame exists only at 30 and 60 (29.97, 59.94)")
        if not 0 <= self.frames < frames_per_day(self.rate, self.drop):
            raise TimecodeError(f"timecode count {self.frames} is outside one day at {self.rate}{self._kind}")

    @property
    def _kind(self) -> str:
        return " drop-frame" if self.drop else ""

    @classmethod
    def for_fps(cls, frames: int, fps: float) -> Timecode:
        """A count at the customary rate and drop flag of ``fps`` (see :func:`rate_of`)."""
        rate, drop = rate_of(fps)
        return cls(frames % frames_per_day(rate, drop), rate, drop)

    @classmethod
    def from_fields(cls, hours: int, minutes: int, seconds: int, frame: int, rate: int, drop: bool) -> Timecode:
        """The count of a label, refused if the label does not exist (out of range or dropped)."""
        label = f"{hours:02d}:{minutes:02d}:{seconds:02d}{';' if drop else ':'}{frame:02d}"
        if not (0 <= hours < 24 and 0 <= minutes < 60 and 0 <= seconds < 60 and 0 <= frame < rate):
            raise TimecodeError(f"timecode {label} does not exist at {rate} fps (fields out of range)")
        total_minutes = hours * 60 + minutes
        count = (total_minutes * 60 + seconds) * rate + frame
        if drop:
            d = _DROPPED.get(rate, 0)
            if seconds == 0 and frame < d and minutes % 10:
                raise TimecodeError(f"timecode {label} is a dropped label at {rate} drop-frame")
            count -= d * (total_minutes - total_minutes // 10)
        return cls(count, rate, drop)

    @classmethod
    def parse(cls, text: str, rate: int, drop: bool | None = None) -> Timecode:
        """``HH:MM:SS:FF`` or ``HH:MM:SS;FF`` (``.``/``,`` also mean drop-frame, as some tools write).

        ``drop`` None: taken from the separator. Given, it must agree with the separator.
        """
        m = _TEXT.match(text.strip())
        if m is None:
            raise TimecodeError(f"timecode {text!r}: expected HH:MM:SS:FF or HH:MM:SS;FF")
        sep_drop = m.group(4) != ":"
        if drop is not None and drop != sep_drop:
            raise TimecodeError(
                f"timecode {text!r}: the separator says {'drop' if sep_drop else 'non-drop'}-frame, "
                f"the rate {'drop' if drop else 'non-drop'}-frame"
            )
        h, mi, s, f = (int(m.group(i)) for i in (1, 2, 3, 5))
        return cls.from_fields(h, mi, s, f, rate, sep_drop)

    @classmethod
    def from_clock(cls, seconds_since_midnight: float, fps: float) -> Timecode:
        """The time-of-day timecode of a clock time, jammed as a camera would be: the label shows the clock.

        Non-drop labels count ``rate`` frames a second; drop-frame labels count the real 29.97/59.94 frames,
        which is what keeps them on the clock.
        """
        if not math.isfinite(seconds_since_midnight) or seconds_since_midnight < 0:
            raise TimecodeError(f"clock time {seconds_since_midnight!r} s: expected seconds since midnight")
        rate, drop = rate_of(fps)
        per_second = rate * 1000 / 1001 if drop else rate
        return cls(math.floor(seconds_since_midnight * per_second) % frames_per_day(rate, drop), rate, drop)

    def fields(self) -> tuple[int, int, int, int]:
        """Hours, minutes, seconds and frame of the label."""
        n = self.frames
        if self.drop:
            d = _DROPPED[self.rate]
            per_10min = self.rate * 600 - 9 * d
            per_min = self.rate * 60 - d
            tens, rest = divmod(n, per_10min)
            n += 9 * d * tens + (d * ((rest - d) // per_min) if rest >= d else 0)
        s, f = divmod(n, self.rate)
        return s // 3600, s // 60 % 60, s % 60, f

    def __str__(self) -> str:
        h, m, s, f = self.fields()
        return f"{h:02d}:{m:02d}:{s:02d}{';' if self.drop else ':'}{f:02d}"

    def __int__(self) -> int:
        return self.frames

    def __add__(self, frames: int) -> Timecode:
        return Timecode((self.frames + int(frames)) % frames_per_day(self.rate, self.drop), self.rate, self.drop)

    def __sub__(self, other: Timecode) -> int:
        """Frames from ``other`` to this one, the short way round midnight."""
        if (other.rate, other.drop) != (self.rate, self.drop):
            raise TimecodeError(f"cannot subtract timecode {other} from {self}: different rates")
        day = frames_per_day(self.rate, self.drop)
        diff = (self.frames - other.frames) % day
        return diff - day if diff > day // 2 else diff


def unwrap(counts: NDArray[np.integer], reference: int, rate: int, drop: bool) -> NDArray[np.int64]:
    """Counts of a take that may run past midnight, made monotonic: a count more than half a day before
    ``reference`` (the take's first count) is the next day's."""
    day = frames_per_day(rate, drop)
    c = np.asarray(counts, dtype=np.int64)
    return np.where(c < reference - day // 2, c + day, c)


def start_timecode(iso_utc: str, fps: float) -> Timecode:
    """Time-of-day timecode (UTC, as a camera jammed to the clock would show) of a take's ``started_utc``;
    ``00:00:00:00`` when the time is unknown. The take's ALE, sets.csv, EXR and the shoot UI all count on
    from this one value."""
    rate, drop = rate_of(fps)
    if not iso_utc:
        return Timecode(0, rate, drop)
    try:
        t = dt.datetime.fromisoformat(iso_utc).astimezone(dt.UTC)
    except ValueError:
        raise TimecodeError(f"start time {iso_utc!r}: expected an ISO 8601 time") from None
    return Timecode.from_clock(t.hour * 3600 + t.minute * 60 + t.second + t.microsecond / 1e6, fps)
