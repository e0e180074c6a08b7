"""The size bench's arithmetic (issue 24) from injected times: ratio to the SGBM pair, stages, write share and
the real-time factor. No timing is measured here."""

from __future__ import annotations

import numpy as np
import pytest

from rigctl.errors import ParameterError
from rigctl.farm.membench import format_speed, phase_peak, speed_summary


def test_ratio_stages_write_share_and_realtime_factor() -> None:
    s = speed_summary(
        depth_s=12.0,
        write_s=3.0,
        stages_s={"cost": 5.0, "aggregation": 2.0, "candidates": 1.5, "refinement": 0.5},
        sgbm_s=0.5,
        fps=25.0,
        workers=10,
    )
    assert s["ratio_depth"] == pytest.approx(24.0)
    assert s["ratio_total"] == pytest.approx(30.0)
    # what the named stages did not account for is "other"; writing is its own stage
    assert s["stages_s"]["other"] == pytest.approx(3.0)
    assert s["stages_s"]["write"] == pytest.approx(3.0)
    assert sum(v for k, v in s["stages_s"].items() if k != "write") == pytest.approx(12.0)
    assert s["write_share"] == pytest.approx(0.2)
    # 15 s per frame set at 25 fps: 375 s of compute per second of footage; ten workers share it
    assert s["realtime_factor"]["1"] == pytest.approx(375.0)
    assert s["realtime_factor"]["10"] == pytest.approx(37.5)
    assert s["hours_per_minute"]["1"] == pytest.approx(375.0 * 60 / 3600)
    assert s["hours_per_minute"]["10"] == pytest.approx(375.0 * 60 / 3600 / 10)
    assert "ratio_cpu" not in s  # only when CPU seconds are given


def test_the_ratio_in_cpu_seconds() -> None:
    s = speed_summary(12.0, 3.0, {}, 0.5, 25.0, 1, cpu=(27.0, 0.9))
    assert s["ratio_cpu"] == pytest.approx(30.0) and s["ratio_total"] == pytest.approx(30.0)
    with pytest.raises(ParameterError):
        speed_summary(12.0, 3.0, {}, 0.5, 25.0, 1, cpu=(27.0, 0.0))


def test_stages_beyond_the_depth_time_leave_no_negative_other() -> None:
    s = speed_summary(1.0, 0.0, {"cost": 0.7, "aggregation": 0.4}, 0.1, 25.0, 1)
    assert s["stages_s"]["other"] == 0.0 and s["write_share"] == 0.0
    assert s["realtime_factor"] == {"1": pytest.approx(25.0)}


@pytest.mark.parametrize(("sgbm_s", "fps", "workers"), [(0.0, 25.0, 1), (0.2, 0.0, 1), (0.2, 25.0, 0)])
def test_refuses_figures_that_would_divide_by_nothing(sgbm_s: float, fps: float, workers: int) -> None:
    with pytest.raises(ParameterError):
        speed_summary(1.0, 1.0, {}, sgbm_s, fps, workers)


def test_the_text_names_the_reference_ratio_and_real_time_factor() -> None:
    times = {"depth": 8.0, "write": 2.0}
    summary = speed_summary(8.0, 2.0, {"cost": 4.0}, 0.25, 25.0, 4, cpu=(15.0, 0.5), write_cpu_s=1.5)
    r = {
        "size": [1920, 1080],
        "preset": "best",
        "cameras": ["c"] * 9,
        "formats": ["exr"],
        "seconds": 10.0,
        "timings_s": times,
        "pixel_levels": {"integer_sweep": 1e9},
        "sgbm": {"seconds": 0.25, "levels": 128, "threads": 2},
        "peak_rss_bytes": 2**30,
        "input_bytes": 2**28,
        "peak_rss_while_building_input_bytes": 2**29,
        "fps": 25.0,
        "workers": 4,
        "summary": summary,
    }
    text = format_speed(r)
    assert "(depth 8.00 s, write 2.00 s: EXR)" in text  # what the write wrote
    assert "SGBM 3WAY pair" in text and "128 levels" in text and "0.250 s" in text
    assert "depth 32.0x" in text and "depth + write 40.0x" in text and "in CPU seconds (depth + write) 30.0x" in text
    assert "write share 20.0 % of the elapsed time (nothing overlaps the write)" in text
    assert "write share 20.0 %" in text and "1.50 CPU s, 10.0 % of the CPU seconds" in text
    assert "250 s of compute per s of footage on one worker, 62.5 on 4 workers" in text


def test_the_writes_cpu_seconds_and_their_share_of_the_frame_sets() -> None:
    s = speed_summary(12.0, 3.0, {}, 0.5, 25.0, 1, cpu=(20.0, 0.5), write_cpu_s=2.5)
    assert s["write_cpu_s"] == pytest.approx(2.5)
    assert s["write_cpu_share"] == pytest.approx(0.125)  # of the frame set's 20 CPU seconds, not of the pair's
    assert s["write_share"] == pytest.approx(0.2)  # the elapsed share stays the elapsed one
    assert "write_cpu_share" not in speed_summary(12.0, 3.0, {}, 0.5, 25.0, 1, cpu=(20.0, 0.5))
    for bad in (-0.1, 20.5):  # a write cannot take more CPU than the frame set it belongs to
        with pytest.raises(ParameterError):
            speed_summary(12.0, 3.0, {}, 0.5, 25.0, 1, cpu=(20.0, 0.5), write_cpu_s=bad)


def test_each_phase_has_its_own_peak() -> None:
    """The bench tells the depth's peak from the write's: a phase's peak counts what it allocated and what was
    held when it started, not what an earlier phase allocated and freed."""
    mib = 2**20

    def big() -> int:
        a = np.ones(256 * mib, np.uint8)  # touched: resident
        return int(a[::4096].sum())

    held = np.ones(64 * mib, np.uint8)
    n, first = phase_peak(big)
    assert n == 256 * mib // 4096
    _, second = phase_peak(lambda: None)
    assert first - second > 200 * mib  # the first phase's array is gone from the second's peak
    assert second > held.nbytes  # what is held across the phases counts in each


def test_the_text_gives_the_depths_and_the_writes_peaks() -> None:
    summary = speed_summary(8.0, 2.0, {}, 0.25, 25.0, 4)
    r = {
        "size": [3840, 2160],
        "preset": "best",
        "cameras": ["c"] * 9,
        "seconds": 10.0,
        "timings_s": {"depth": 8.0, "write": 2.0},
        "pixel_levels": {},
        "sgbm": {"seconds": 0.25, "levels": 128, "threads": 2},
        "peak_rss_bytes": 3 * 2**30,
        "peak_rss_depth_bytes": 3 * 2**30,
        "peak_rss_write_bytes": 2**30,
        "input_bytes": 2**28,
        "peak_rss_while_building_input_bytes": 2**29,
        "fps": 25.0,
        "workers": 4,
        "summary": summary,
    }
    assert "peak memory 3.00 GiB (depth 3.00 GiB, write 1.00 GiB; input images 0.25 GiB" in format_speed(r)
