"""The Camera contract against simulated cameras, plus every timing setting of the simulator."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from camera_contract import CONTRACT  # type: ignore[import-not-found]
from rigctl.simulators import burnin

from rigctl.interfaces import CaptureFormat
from rigctl.registry import open_cameras
from rigctl.rig import load_rig

RIG = load_rig("sim-3x3")
FMT = CaptureFormat(RIG.width_px, RIG.height_px, "UYVY", RIG.fps)
FAST = ["motion=false", "noise=0"]


@pytest.fixture(scope="module")
def device_set():  # type: ignore[no-untyped-def]
    ds = open_cameras(RIG, FAST)
    yield ds
    ds.close()


@pytest.mark.parametrize("check", CONTRACT, ids=[c.__name__ for c in CONTRACT])
def test_contract(check, device_set) -> None:  # type: ignore[no-untyped-def]
    from rigctl.simulators.camera import SimCamera

    array = next(iter(device_set.cameras.values())).array

    def make():  # type: ignore[no-untyped-def]
        return SimCamera("r1c1", array), FMT

    check(make)


def record(settings: list[str], frames: int, cameras: list[str] | None = None) -> dict[str, list]:  # type: ignore[type-arg]
    """Read ``frames`` frames from every camera at once; per camera (seq, capture_ns, burnt id)."""
    ds = open_cameras(RIG, FAST + settings, cameras)
    out: dict[str, list] = {}  # type: ignore[type-arg]
    try:
        for cam in ds.cameras.values():
            cam.open()
            cam.configure(FMT)
        for cam in ds.cameras.values():
            cam.start()

        def run(cam) -> None:  # type: ignore[no-untyped-def]
            got = []
            buf = bytearray(FMT.bytes_per_frame)
            while len(got) < frames:
                f = cam.read(3.0, memoryview(buf))
                if f is None:
                    got.append(None)
                    continue
                bid = burnin.read(np.frombuffer(f.data, np.uint8).reshape(FMT.height, -1), FMT.width)
                got.append((f.sequence, f.capture_ns, bid))
            out[cam.name] = got

        threads = [threading.Thread(target=run, args=(c,)) for c in ds.cameras.values()]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        ds.close()
    return out


def test_drops_at_given_sequence_numbers_and_nowhere_else() -> None:
    got = record(["drops.r0c1=[3,4,9]"], 12)
    seqs = {name: [g[0] for g in frames] for name, frames in got.items()}
    assert seqs["r0c1"][:9] == [0, 1, 2, 5, 6, 7, 8, 10, 11]
    for name, s in seqs.items():
        if name != "r0c1":
            assert s == list(range(12)), name
    # the burnt-in ids are the delivered frames' own: nothing reordered or duplicated
    for frames in got.values():
        assert all(g[2] is not None and g[2].sequence == g[0] for g in frames)
    cams = sorted(got)
    assert {g[2].camera_index for g in got["r0c1"]} == {cams.index("r0c1")}


def test_skew_and_jitter_within_settings() -> None:
    got = record(["skew_us.r2c2=4000", "jitter_us=200"], 15)
    ref = np.array([g[1] for g in got["r0c0"]], dtype=np.int64)
    skewed = np.array([g[1] for g in got["r2c2"]], dtype=np.int64)
    other = np.array([g[1] for g in got["r1c1"]], dtype=np.int64)
    n = min(len(ref), len(skewed), len(other))
    d_skew = (skewed[:n] - ref[:n]) / 1e3
    d_other = (other[:n] - ref[:n]) / 1e3
    assert np.mean(d_skew) == pytest.approx(4000, abs=150)
    assert np.abs(d_other).max() < 6 * 200 * np.sqrt(2)  # jitter only, sigma 200 us on each side
    assert np.std(d_other) == pytest.approx(200 * np.sqrt(2), rel=0.6)
    assert np.abs(d_other).max() > 0  # jitter is there at all


def test_start_up_stagger_delays_first_frames_by_whole_periods() -> None:
    got = record(["stagger_ms=200", "jitter_us=0", "seed=3"], 8)
    firsts = np.array([g[0][1] for g in got.values()], dtype=np.int64)
    period = 1e9 / FMT.fps
    offsets = (firsts - firsts.min()) / period
    assert np.allclose(offsets, np.round(offsets), atol=0.02), "stagger is in whole frame periods (genlock)"
    assert offsets.max() >= 1, "seed 3 staggers at least one camera"
    assert offsets.max() <= 5


def test_signal_loss_over_its_interval() -> None:
    got = record(["signal_loss.r1c0=[0.2,0.6]", "jitter_us=0"], 20, cameras=["r1c0", "r1c1"])
    lost = [g for g in got["r1c0"] if g is not None]
    ref = [g for g in got["r1c1"] if g is not None]
    t0 = ref[0][1]
    times = np.array([(g[1] - t0) / 1e9 for g in lost])
    # the stream's origin lies up to two periods before the first delivered frame: allow for that
    p = 1 / FMT.fps
    gap_at = int(np.argmax(np.diff(times)))
    assert 0.2 - 2 * p - 0.01 <= times[gap_at] + p <= 0.2 + 0.01
    assert np.diff(times)[gap_at] == pytest.approx(0.4 + p, abs=0.01)
    assert np.all(np.delete(np.diff(times), gap_at) == pytest.approx(p, abs=0.005))
    # sequence numbers continue without a gap across it: nothing was captured, nothing was dropped
    assert [g[0] for g in lost] == list(range(len(lost)))


def read_twice(settings: list[str], pause_s: float):  # type: ignore[no-untyped-def]
    """One camera's first frame, the one it gives when read again ``pause_s`` later, and its source drops."""
    import time

    ds = open_cameras(RIG, FAST + settings, ["r0c0"])
    cam = ds.cameras["r0c0"]
    try:
        cam.open()
        cam.configure(FMT)
        cam.start()
        first = cam.read(2.0)
        time.sleep(pause_s)
        after = cam.read(2.0)
        assert first is not None and after is not None
        return first, after, cam.status().source_drops
    finally:
        ds.close()


def test_slow_reader_loses_frames_at_the_source_as_sequence_gaps() -> None:
    first, after, drops = read_twice([], 0.8)  # 20 frame periods with 8 driver buffers: about 12 frames lost
    gap = after.sequence - first.sequence - 1
    assert 9 <= gap <= 14
    assert drops == gap


def test_deterministic_frames_sit_on_the_simulated_grid_with_the_faults_as_set() -> None:
    """``deterministic=true``: capture times are the grid's from a fixed origin (plus the set skew), host times
    the capture plus the latency, and drops and signal losses fall where they are set."""
    from rigctl.simulators.timing import SIMULATED_ORIGIN_NS

    settings = ["deterministic=true", "jitter_us=0", "drops.r0c1=[3,4]", "signal_loss.r1c0=[0.2,0.6]"]
    got = record([*settings, "skew_us.r2c2=3000"], 12, cameras=["r0c0", "r0c1", "r1c0", "r2c2"])
    period = round(1e9 / FMT.fps)
    assert [g[0] for g in got["r0c0"]] == list(range(12))
    assert [g[1] for g in got["r0c0"]] == [SIMULATED_ORIGIN_NS + k * period for k in range(12)]
    assert [g[1] - SIMULATED_ORIGIN_NS for g in got["r2c2"]] == [k * period + 3_000_000 for k in range(12)]
    assert [g[0] for g in got["r0c1"]] == [0, 1, 2, *range(5, 14)]
    # no signal from 0.2 s to 0.6 s (grid slots 5 to 14): nothing captured, the sequence carries on
    slots = [(g[1] - SIMULATED_ORIGIN_NS) // period for g in got["r1c0"]]
    assert slots == [0, 1, 2, 3, 4, *range(15, 22)] and [g[0] for g in got["r1c0"]] == list(range(12))
    assert got == record([*settings, "skew_us.r2c2=3000"], 12, cameras=["r0c0", "r0c1", "r1c0", "r2c2"])


def test_deterministic_slow_reader_loses_nothing() -> None:
    """The live behaviour above, paced by the reader instead: however late it reads, the next frame comes."""
    first, after, drops = read_twice(["deterministic=true", "jitter_us=0"], 0.4)  # live: two frames lost
    assert after.sequence == first.sequence + 1 and drops == 0
    assert after.capture_ns - first.capture_ns == round(1e9 / FMT.fps)
    assert after.host_ns - after.capture_ns == 800_000  # the simulated latency, not this machine's


@pytest.mark.parametrize("motion", ["true", "false"])
def test_closing_the_devices_stops_and_waits_for_the_background_render(motion: str) -> None:
    """A process that closed its devices and exits must not leave the simulator's render thread inside OpenCV:
    the C++ runtime then aborted it after the command's own error line (``rigctl control`` with a bad bridge
    address: "terminate called without an active exception", exit 134, on a loaded machine). Opened and
    closed at once, as that command does, no render thread is left running (the simulator's defaults, motion
    on, and a still scene)."""
    ds = open_cameras(RIG, ["noise=0", f"motion={motion}"])
    assert any(t.name == "sim-render" and t.is_alive() for t in threading.enumerate())  # rendering as it opened
    ds.close()
    assert not [t for t in threading.enumerate() if t.name == "sim-render" and t.is_alive()]
