"""Timecode: SMPTE ST 12-1 examples, agreement with an independent library at every rate the rig shoots,
and the path of a timecode from the driver's integers through a take to frame sets and sidecars."""

from __future__ import annotations

import pytest
from timecode import Timecode as Reference  # the `timecode` package: an independent implementation

from rigctl.timecode import Timecode, TimecodeError, frames_per_day, rate_of, start_timecode

# the rates of the issue: (fps as the rig states it, the reference library's name for it)
RATES = [(24000 / 1001, "23.976"), (25.0, "25"), (30000 / 1001, "29.97"), (50.0, "50"), (60000 / 1001, "59.94")]


@pytest.mark.parametrize(
    ("fps", "rate", "drop"),
    [(23.976, 24, False), (24000 / 1001, 24, False), (25, 25, False), (29.97, 30, True), (30000 / 1001, 30, True),
     (30, 30, False), (50, 50, False), (59.94, 60, True), (60, 60, False)],
)  # fmt: skip
def test_rate_of(fps: float, rate: int, drop: bool) -> None:
    assert rate_of(fps) == (rate, drop)


def test_st12_drop_frame_examples_at_29_97() -> None:
    p = lambda s: Timecode.parse(s, 30)  # noqa: E731
    # the first two labels of each minute are dropped, except every tenth minute
    assert str(p("00:00:59;29") + 1) == "00:01:00;02"
    assert str(p("00:09:59;29") + 1) == "00:10:00;00"
    assert str(p("00:19:59;29") + 1) == "00:20:00;00"
    assert str(p("01:00:59;29") + 1) == "01:01:00;02"
    # 17982 frames per ten minutes, 107892 an hour, 2589408 a day
    assert p("00:10:00;00").frames == 17982
    assert p("01:00:00;00").frames == 107892
    assert p("23:59:59;29").frames == 2589407 == frames_per_day(30, True) - 1
    assert str(p("23:59:59;29") + 1) == "00:00:00;00"  # wraps at midnight
    for dropped in ("00:01:00;00", "00:01:00;01", "12:59:00;01"):
        with pytest.raises(TimecodeError, match="dropped label"):
            p(dropped)
    assert p("00:10:00;01").frames == 17983  # minute 10 keeps its labels


def test_st12_drop_frame_examples_at_59_94() -> None:
    p = lambda s: Timecode.parse(s, 60)  # noqa: E731
    assert str(p("00:00:59;59") + 1) == "00:01:00;04"  # four labels dropped at 60
    assert p("01:00:00;00").frames == 215784
    with pytest.raises(TimecodeError, match="dropped label"):
        p("00:01:00;03")


def test_the_labels_that_collided_are_consecutive_frames() -> None:
    """The issue's case: 00:00:16;29 and 00:00:17;00 (and 49;29 / 50;00) once mapped to one number."""
    for a, b in (("00:00:16;29", "00:00:17;00"), ("00:00:49;29", "00:00:50;00"), ("00:00:59;29", "00:01:00;02")):
        ta, tb = Timecode.parse(a, 30), Timecode.parse(b, 30)
        assert tb.frames == ta.frames + 1 and tb - ta == 1


@pytest.mark.parametrize(("fps", "name"), RATES)
def test_every_label_agrees_with_the_reference_library(fps: float, name: str) -> None:
    """Count -> label -> count over the first eleven minutes (every drop-frame pattern) and across midnight."""
    rate, drop = rate_of(fps)
    day = frames_per_day(rate, drop)
    span = 11 * 60 * rate
    for n in [*range(span), *range(day - 3 * rate, day)]:
        ours = Timecode(n, rate, drop)
        ref = Reference(name, frames=n + 1)  # the library counts from 1
        assert str(ours) == str(ref), n
        assert Timecode.parse(str(ref), rate).frames == ref.frame_number == n


@pytest.mark.parametrize(("fps", "name"), RATES)
def test_labels_parse_to_distinct_consecutive_counts(fps: float, name: str) -> None:
    """Frame sets are built on counts: every existing label of an hour maps to its own count, in order."""
    rate, drop = rate_of(fps)
    counts = []
    for m in range(60):
        for s in range(60):
            for f in range(rate):
                try:
                    counts.append(Timecode.from_fields(1, m, s, f, rate, drop).frames)
                except TimecodeError:
                    assert drop and s == 0 and m % 10 and f < rate // 15
    assert counts == list(range(counts[0], counts[0] + len(counts)))
    assert counts[0] == Reference(name, "01:00:00;00" if drop else "01:00:00:00").frame_number


def test_bad_labels_get_one_clear_line() -> None:
    for text, why in (
        ("24:00:00:00", "out of range"),
        ("00:00:00:25", "out of range"),
        ("0:00:00:00", "expected HH:MM:SS:FF"),
        ("nonsense", "expected HH:MM:SS:FF"),
    ):
        with pytest.raises(TimecodeError, match=why):
            Timecode.parse(text, 25)
    with pytest.raises(TimecodeError, match="drop-frame exists only"):
        Timecode.parse("00:00:00;00", 25)
    with pytest.raises(TimecodeError, match="separator says non-drop"):
        Timecode.parse("00:00:00:00", 30, drop=True)


def test_time_of_day_start_shows_the_clock() -> None:
    # a camera jammed at 10:20:30.5 UTC shows 10:20:30 and half a second's frames
    assert str(start_timecode("2026-05-01T10:20:30.500+00:00", 25)) == "10:20:30:12"
    assert str(start_timecode("2026-05-01T10:20:30.500+00:00", 24000 / 1001)) == "10:20:30:12"
    # drop-frame labels keep to the clock, within 86 ms a day, at 29.97 and 59.94 (a non-drop count of the
    # real frames would be 75 s behind at 23:10)
    for fps in (30000 / 1001, 60000 / 1001):
        for clock in ("00:00:00.000", "00:09:59.990", "07:31:12.250", "23:10:00.000", "23:59:59.900"):
            tc = start_timecode(f"2026-05-01T{clock}+00:00", fps)
            h, m, s, f = tc.fields()
            hh, mm, ss = clock.split(":")
            label_s = h * 3600 + m * 60 + s + f / tc.rate
            assert tc.drop and abs(label_s - (int(hh) * 3600 + int(mm) * 60 + float(ss))) < 0.09
    # a local time is converted to UTC, as started_utc always is
    assert str(start_timecode("2026-05-01T12:00:00+02:00", 50)) == "10:00:00:00"
    assert str(start_timecode("", 29.97)) == "00:00:00;00"
