"""Scene states of the simulated array rendered on demand or in the background: each exactly once, the
same bytes whoever renders them, and a schedule of which state a frame shows that never depends on how far
rendering has got. Renders are injected and held back with events: no test depends on timing."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from rigctl.simulators.array import SimArray
from rigctl.simulators.camera import SimCamera
from rigctl.simulators.settings import SimSettings
from rigctl.simulators.states import DiskCache, Frames, StateStore

from rigctl.interfaces import CaptureFormat
from rigctl.rig import load_rig, rig_from_dict

NAMES = ["a", "b"]


class FakeRender:
    """Frames that say which state they are; each call recorded, and held until ``gate`` is set."""

    def __init__(self, held: bool = False) -> None:
        self.calls: list[int] = []
        self.gate = threading.Event()
        self.entered = threading.Event()
        if not held:
            self.gate.set()

    def __call__(self, state: int) -> Frames:
        self.calls.append(state)
        self.entered.set()
        self.gate.wait()
        return [np.full(8, state * 10 + i, dtype=np.uint8) for i in range(len(NAMES))]


def test_a_state_asked_for_twice_at_once_is_rendered_once() -> None:
    render = FakeRender(held=True)
    store = StateStore(render)
    got: list[Frames] = []
    first = threading.Thread(target=lambda: got.append(store.get(3)))
    first.start()
    render.entered.wait()  # the first caller is inside the render: the second must wait for it
    second = threading.Thread(target=lambda: got.append(store.get(3)))
    second.start()
    assert not store.ready(3)
    render.gate.set()
    first.join()
    second.join()
    assert render.calls == [3]
    assert got[0] is got[1] and int(got[0][1][0]) == 31


def test_background_renders_in_order_and_skips_what_a_camera_already_asked_for() -> None:
    render = FakeRender()
    store = StateStore(render)
    store.get(2)  # a camera needed state 2 before the background got there
    store.start([0, 1, 2, 3])
    store.join()
    assert render.calls == [2, 0, 1, 3]
    assert all(store.ready(s) for s in range(4)) and store.error is None


def test_wait_gives_up_on_a_render_under_way_and_succeeds_after_it() -> None:
    render = FakeRender(held=True)
    store = StateStore(render)
    store.start([0])
    render.entered.wait()
    assert store.wait(0, 0.0) is False  # under way, not done: the reader returns no frame this time
    render.gate.set()
    store.join()
    assert store.wait(0, 0.0) is True
    assert render.calls == [0]


def test_wait_renders_a_state_nobody_is_rendering() -> None:
    render = FakeRender()
    store = StateStore(render)
    assert store.wait(5, 0.0) is True
    assert render.calls == [5]


def test_a_failed_render_reaches_the_caller_and_the_next_caller_tries_again() -> None:
    attempts: list[int] = []

    def flaky(state: int) -> Frames:
        attempts.append(state)
        if len(attempts) == 1:
            raise MemoryError("out of memory")
        return [np.zeros(8, np.uint8) for _ in NAMES]

    store = StateStore(flaky)
    with pytest.raises(MemoryError):
        store.get(0)
    assert not store.ready(0)
    assert len(store.get(0)) == 2 and attempts == [0, 0]


def test_the_disk_cache_gives_the_same_bytes_and_a_damaged_file_is_rendered_again(tmp_path: Path) -> None:
    disk = DiskCache(tmp_path, NAMES, 8)
    first = StateStore(FakeRender(), disk)
    made = first.get(1)
    again = FakeRender()
    loaded = StateStore(again, disk).get(1)
    assert again.calls == [] and all(np.array_equal(x, y) for x, y in zip(made, loaded, strict=True))
    (tmp_path / "state-1.npz").write_bytes(b"not a zip file")
    third = FakeRender()
    assert int(StateStore(third, disk).get(1)[0][0]) == 10 and third.calls == [1]


def test_the_cache_folder_follows_the_inputs_and_can_be_switched_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    source = tmp_path / "source.py"
    source.write_text("x = 1\n")
    monkeypatch.setenv("RIGCTL_SIM_CACHE", str(tmp_path / "cache"))
    a = DiskCache.for_inputs({"seed": 1}, [source], NAMES, 8)
    b = DiskCache.for_inputs({"seed": 2}, [source], NAMES, 8)
    assert a is not None and b is not None and a.folder != b.folder
    assert a.folder.parent == tmp_path / "cache"
    source.write_text("x = 2\n")  # a changed simulator renders anew
    c = DiskCache.for_inputs({"seed": 1}, [source], NAMES, 8)
    assert c is not None and c.folder != a.folder
    monkeypatch.setenv("RIGCTL_SIM_CACHE", "off")
    assert DiskCache.for_inputs({"seed": 1}, [source], NAMES, 8) is None


# ---- which state a frame shows ----------------------------------------------------------------------


def test_the_motion_joins_one_pose_at_a_time_on_a_fixed_schedule() -> None:
    arr = SimArray(load_rig("sim-3x3"), SimSettings(motion_states=10, motion_ramp_s=2.0))
    ramp = arr.ramp_frames
    assert ramp == 50 and not arr.up_front  # 2 s at 25 fps
    per_cycle = 40  # 1.6 s at 25 fps: 4 frames per pose
    free = [(f % per_cycle) * 10 // per_cycle for f in range(2000)]
    shown = [arr.state_of(f) for f in range(2000)]
    assert set(shown[:ramp]) == {0}  # still until the second pose has joined
    for f in range(2000):
        assert shown[f] == min(free[f], f // ramp)  # the cycle holds at the latest pose that has joined
    assert shown[9 * ramp :] == free[9 * ramp :]  # then the full motion
    assert max(shown[ramp : 2 * ramp]) == 1


def test_without_the_ramp_every_state_is_needed_from_the_first_frame() -> None:
    rig = load_rig("sim-3x3")
    free = SimArray(rig, SimSettings(motion_ramp_s=0))
    assert free.ramp_frames == 0 and free.up_front
    assert [free.state_of(f) for f in range(40)] == [f * 10 // 40 for f in range(40)]
    charuco = SimArray(rig, SimSettings(scene="charuco", board_poses=5))
    assert charuco.up_front and [charuco.state_of(f) for f in range(7)] == [0, 1, 2, 3, 4, 0, 1]
    still = SimArray(rig, SimSettings(motion=False))
    assert still.up_front and still.state_of(12345) == 0


# ---- the camera: streams at once, its first frame waits for its picture ----------------------------


def small_rig():  # type: ignore[no-untyped-def]
    data = load_rig("sim-3x3").to_dict()
    data["format"].update(width_px=128, height_px=72)
    return rig_from_dict(data)


def test_a_camera_starts_at_once_and_its_first_frame_waits_for_the_first_state() -> None:
    rig = small_rig()
    arr = SimArray(rig, SimSettings(noise=0))
    size = arr.format.bytes_per_frame
    shape = (72, 256)
    calls: list[int] = []
    gate, entered = threading.Event(), threading.Event()

    def render(state: int) -> Frames:
        calls.append(state)
        entered.set()
        gate.wait()
        return [np.full(shape, 100 + state, np.uint8) for _ in arr.names]

    arr.__dict__["states"] = StateStore(render)  # the array's renders, injected
    cam = SimCamera("r1c1", arr, buffers=1_000_000)  # a reader never counts as late here: no scheduling luck
    cam.open()
    cam.configure(CaptureFormat(128, 72, "UYVY", rig.fps))
    cam.start()  # returns with nothing rendered yet
    entered.wait()  # the background thread is rendering the first state
    buf = memoryview(bytearray(size))
    assert cam.read(0.0, buf) is None  # no picture yet: no frame, and no frame lost either
    gate.set()
    frame = cam.read(30.0, buf)
    cam.stop()
    cam.close()
    assert frame is not None and frame.sequence == 0  # the stream begins with its first picture
    assert cam.status().source_drops == 0
    body = np.frombuffer(frame.data, np.uint8)[size // 2 :]  # below the burnt-in ids
    assert np.all(body == 100)  # state 0, as the schedule says for the stream's first frames
    assert calls[0] == 0 and calls.count(0) == 1


def test_a_closed_stores_queued_camera_work_is_dropped_not_done() -> None:
    """A state's render queues every camera's work in a pool, and a process exiting waits for that queue:
    after ``stop`` the work not begun is refused (nine 8K cameras rendered for minutes after ``record``'s
    preflight refused)."""
    from concurrent.futures import ThreadPoolExecutor

    from rigctl.simulators.states import RenderStopped

    done: list[int] = []
    begun, release = threading.Event(), threading.Event()

    def camera(n: int) -> int:
        begun.set()
        release.wait(10)
        done.append(n)
        return n

    store = StateStore(lambda state: [])
    assert store.unless_stopped(lambda a, b: a + b, 2, 3) == 5
    with ThreadPoolExecutor(1) as pool:
        futures = [pool.submit(store.unless_stopped, camera, n) for n in range(5)]
        assert begun.wait(10)
        store.stop()  # camera 0 under way: it finishes; 1 to 4 are refused when their turn comes
        release.set()
    assert done == [0] and futures[0].result() == 0
    for f in futures[1:]:
        with pytest.raises(RenderStopped):
            f.result()
