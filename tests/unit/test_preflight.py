"""Preflight's decisions on injected figures (no test here touches this machine's disk speed), the speed
measurement's arithmetic on an injected clock, and the writer queue trend."""

from __future__ import annotations

from pathlib import Path

import pytest

from rigctl.capture.preflight import (
    GO,
    REFUSE,
    WARN,
    WriteSpeed,
    check_destinations,
    decide,
    dirty_headroom_bytes,
    measure_write,
)
from rigctl.take.trend import QueueTrend

MB = 1e6
GB = 10**9
NEED = 233 * MB  # nine 960x540 UYVY cameras at 25 fps: the simulated rig
HERE = Path("/takes")


def speed(*mb_s: float) -> WriteSpeed:
    return WriteSpeed(tuple(v * MB for v in mb_s))


def test_a_disk_faster_than_the_cameras_is_a_go_with_its_figures() -> None:
    v = decide(HERE, 9, NEED, None, speed(300, 310, 320, 290, 305), 500 * GB, 4 * GB)
    assert v.outcome == GO and v.reason == "keeps up"
    assert "median 305 MB/s" in v.message and "233 MB/s" in v.message
    assert v.falls_behind_after_s is None


def test_a_planned_take_the_buffers_hold_is_a_go_even_on_a_slow_disk() -> None:
    """The issue's case: 50 frame sets (2 s) on a disk measured at 141 MB/s; 3.6 GB of buffers absorb it."""
    v = decide(HERE, 9, NEED, 2.0, speed(141, 150, 160, 135), 80 * GB, int(3.6 * GB))
    assert v.outcome == GO and v.reason == "absorbed"
    assert "absorb" in v.message


def test_a_planned_take_on_no_measurable_speed_at_all_is_still_recorded_when_memory_holds_it() -> None:
    v = decide(HERE, 9, NEED, 2.0, speed(1, 1, 1), 80 * GB, int(3.6 * GB))
    assert v.outcome == GO


def test_slower_than_needed_for_an_open_ended_take_warns_when_it_will_fall_behind() -> None:
    # p20 of these samples is 180 MB/s: 53 MB/s short of the need, 2.65 GB of buffers last 50 s
    v = decide(HERE, 9, NEED, None, speed(180, 180, 200, 220, 240), 500 * GB, int(2.65 * GB))
    assert v.outcome == WARN and v.reason == "falls behind"
    assert v.falls_behind_after_s == pytest.approx(2.65e9 / (NEED - 180 * MB))
    assert "may fall behind after about 50 s" in v.message


def test_a_planned_take_longer_than_the_buffers_last_warns_with_the_time() -> None:
    v = decide(HERE, 9, NEED, 600.0, speed(200, 200, 200), 500 * GB, 1 * GB)
    assert v.outcome == WARN and "after about 30 s" in v.message


def test_refused_when_the_destination_cannot_be_written() -> None:
    v = decide(HERE, 9, NEED, None, None, 0, 0, error="Permission denied")
    assert v.outcome == REFUSE and v.reason == "not writable" and not v.forcible
    assert "cannot write: Permission denied" in v.message


def test_refused_when_the_planned_length_does_not_fit() -> None:
    v = decide(HERE, 9, NEED, 3600.0, speed(2000, 2000, 2000), 100 * GB, 4 * GB)
    assert v.outcome == REFUSE and v.reason == "no space" and v.forcible
    assert "room for 7.2 min" in v.message and "needs 60.0 min" in v.message


def test_refused_when_far_below_the_need_of_an_open_ended_take() -> None:
    v = decide(HERE, 9, NEED, None, speed(60, 70, 80), 500 * GB, 4 * GB)
    assert v.outcome == REFUSE and v.reason == "far below" and v.forcible
    assert "--force" in v.message and "median 70 MB/s" in v.message


def test_far_below_is_not_refused_when_the_planned_take_fits_in_memory() -> None:
    v = decide(HERE, 9, NEED, 5.0, speed(60, 70, 80), 500 * GB, 4 * GB)
    assert v.outcome == GO


def test_low_space_on_an_open_ended_take_warns() -> None:
    v = decide(HERE, 9, NEED, None, speed(900, 900, 900), 50 * GB, 4 * GB)
    assert v.outcome == WARN and v.reason == "low space" and "3.6 min" in v.message


def test_report_outcome_is_the_worst_destination(tmp_path: Path) -> None:
    fast, slow = tmp_path / "fast", tmp_path / "slow"
    fast.mkdir()
    slow.mkdir()
    speeds = {fast: speed(900, 900, 900), slow: speed(0.1, 0.1, 0.1)}
    report = check_destinations(
        {fast: ["a"] * 5, slow: ["b"] * 4}, 1 * MB, None, speeds, dirty_headroom=0, free_space=lambda _: 500 * GB
    )
    assert [v.outcome for v in report.verdicts] == [GO, REFUSE]
    assert report.outcome == REFUSE and not report.ok and report.forcible
    assert report.problems == [report.verdicts[1].message]


def test_a_destination_that_cannot_be_created_is_refused_naming_it(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    target = blocker / "takes"

    def measure(folder: Path) -> WriteSpeed:
        return measure_write(folder)

    report = check_destinations({target: ["a"]}, NEED, None, None, dirty_headroom=0, measure=measure)
    assert report.outcome == REFUSE and not report.forcible
    assert str(target) in report.problems[0] and "cannot write" in report.problems[0]


def test_percentiles_of_the_samples() -> None:
    s = speed(100, 400, 200, 300, 500)
    assert s.median_bps == 300 * MB
    assert s.low_bps == pytest.approx(180 * MB)  # p20 between the lowest two


def test_measurement_times_each_sample_and_stops_on_its_budget(tmp_path: Path) -> None:
    """On an injected clock where each sample takes longer, the samples are what the clock says, and
    sampling stops once the budget is spent (never fewer than three samples)."""
    ticks = iter(range(1000))

    def clock() -> float:
        return float(next(ticks))

    got = measure_write(tmp_path, samples=10, sample_bytes=4 << 20, budget_s=5.0, clock=clock)
    # per sample the clock reads t0, then the end, then the budget check: every sample spans 1 tick
    assert len(got.samples_bps) == 3 and all(v == pytest.approx(4 << 20) for v in got.samples_bps)
    assert not list(tmp_path.iterdir())  # the test file is removed


def test_dirty_headroom_from_meminfo_and_ratios() -> None:
    meminfo = "MemTotal: 24000000 kB\nMemAvailable: 20000000 kB\nDirty: 1000 kB\nWriteback: 0 kB\n"
    got = dirty_headroom_bytes(meminfo, (0, 10, 0, 20))
    avail = 20_000_000 * 1024
    assert got == (avail * 10 // 100 + avail * 20 // 100) // 2 - 1000 * 1024
    assert dirty_headroom_bytes(meminfo, (0, 10, 2 << 30, 20)) == (avail * 10 // 100 + (2 << 30)) // 2 - 1000 * 1024


def test_queue_trend_gives_time_to_the_first_drop() -> None:
    trend = QueueTrend(capacity=25)
    for i in range(11):  # 0.2 s apart, growing 2 frames per second
        trend.add(100 + i * 0.2, round(i * 0.4))
    assert trend.slope() == pytest.approx(2.0, rel=0.1)
    assert trend.seconds_to_full() == pytest.approx((25 - 4) / 2.0, rel=0.1)


def test_queue_trend_is_quiet_while_steady_and_zero_when_full() -> None:
    trend = QueueTrend(capacity=25)
    for i in range(20):
        trend.add(i * 0.2, 3 + (i % 2))  # one frame of noise
    assert trend.seconds_to_full() is None
    trend.add(4.0, 25)
    assert trend.seconds_to_full() == 0.0


def test_an_unfinished_demo_folder_is_replaced_without_flags_a_finished_one_is_kept(tmp_path: Path) -> None:
    from rigctl.demo import MARKER, prepare_folder
    from rigctl.errors import ParameterError

    out = tmp_path / "demo"
    with prepare_folder(out, fresh=False):
        assert (out / MARKER).exists()
        (out / "takes").mkdir()  # a step failed here: no report
    with prepare_folder(out, fresh=False):
        assert not (out / "takes").exists() and (out / MARKER).exists()
    (out / "report.md").write_text("# finished\n")
    with pytest.raises(ParameterError, match="exists and is not empty"), prepare_folder(out, fresh=False):
        pass
    other = tmp_path / "mine"
    other.mkdir()
    (other / "keep.txt").write_text("not a demo")
    for fresh in (False, True):  # somebody's folder is never cleared, --fresh or not
        with pytest.raises(ParameterError, match="holds no demo"), prepare_folder(other, fresh=fresh):
            pass
    assert (other / "keep.txt").read_text() == "not a demo"
    with prepare_folder(out, fresh=True):  # a finished demo is replaced with --fresh
        assert not (out / "report.md").exists() and (out / MARKER).exists()


def test_a_second_demo_on_a_folder_being_written_is_refused_and_clears_nothing(tmp_path: Path) -> None:
    from rigctl.demo import MARKER, prepare_folder
    from rigctl.errors import OutputError

    out = tmp_path / "demo"
    with prepare_folder(out, fresh=False):
        (out / "takes").mkdir()  # the first demo at work: unfinished, which a demo would otherwise replace
        with pytest.raises(OutputError, match="another rigctl run is writing this folder"), prepare_folder(out, True):
            pass
        assert (out / "takes").is_dir() and (out / MARKER).exists()
    with prepare_folder(out, fresh=False):  # the first has ended: its lock went with it
        assert not (out / "takes").exists()
