"""What every tally output and every camera-control path must do, whatever carries it.

The checks take a harness: the implementation under test on a real line (a pseudo-terminal pair or a UDP
socket) with a simulated device at the other end that reports what it received. The protocols are in
``rigctl.interfaces``: ``TallyOutput.send`` sends the whole state and raises ``DeviceError`` when the line
fails; ``CameraControl.apply`` answers one result per camera and setting, turns a camera it cannot reach
into a FAILED result, and never reports CONFIRMED on a path that cannot read values back.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import pytest

from rigctl.errors import DeviceError
from rigctl.interfaces import CameraControl, SettingState, TallyOutput, TallyState

Lamps = dict[str, tuple[bool, bool]]  # camera -> (on program, on preview)


@dataclass
class TallyHarness:
    output: TallyOutput
    cameras: list[str]
    received: Callable[[], Lamps | None]  # the receiver's latest complete state, None before one arrived
    lose_line: Callable[[], None] | None  # unplug the line; None where the transport has no line (UDP)


def wait_for(h: TallyHarness, want: Lamps, timeout: float = 10.0) -> Lamps | None:
    """The receiver's state once it equals ``want`` (or the last one seen at the timeout: a generous bound,
    the line is local)."""
    deadline = time.monotonic() + timeout
    got = h.received()
    while got != want and time.monotonic() < deadline:
        time.sleep(0.01)
        got = h.received()
    return got


def lamps(cameras: list[str], state: TallyState) -> Lamps:
    return {n: (n in state.program, n in state.preview) for n in cameras}


def check_state_arrives_whole(h: TallyHarness) -> None:
    """Each send replaces the receiver's state: a camera left out of the new state goes dark."""
    a = TallyState(program=frozenset({h.cameras[0]}), preview=frozenset({h.cameras[1], h.cameras[2]}))
    b = TallyState(program=frozenset({h.cameras[2]}), preview=frozenset({h.cameras[-1]}))
    h.output.send(a)
    assert wait_for(h, lamps(h.cameras, a)) == lamps(h.cameras, a)
    h.output.send(b)
    assert wait_for(h, lamps(h.cameras, b)) == lamps(h.cameras, b)


def check_empty_state_clears_every_lamp(h: TallyHarness) -> None:
    h.output.send(TallyState.recording(h.cameras))
    assert wait_for(h, lamps(h.cameras, TallyState.recording(h.cameras))) == {n: (True, False) for n in h.cameras}
    h.output.send(TallyState())
    assert wait_for(h, lamps(h.cameras, TallyState())) == {n: (False, False) for n in h.cameras}


def check_a_lost_line_is_a_device_error(h: TallyHarness) -> None:
    """After the line goes, ``send`` raises DeviceError (the tally service reopens on it); a later close is
    quiet."""
    assert h.lose_line is not None
    h.output.send(TallyState.recording(h.cameras))
    h.lose_line()
    with pytest.raises(DeviceError):
        for _ in range(3):  # a write can land in the kernel's buffer once before the line reports its loss
            h.output.send(TallyState(program=frozenset({h.cameras[0]})))
    h.output.close()


def check_close_is_quiet_and_repeatable(h: TallyHarness) -> None:
    h.output.send(TallyState())
    h.output.close()
    h.output.close()


TALLY_CONTRACT = [check_state_arrives_whole, check_empty_state_clears_every_lamp, check_close_is_quiet_and_repeatable]
TALLY_LINE_CONTRACT = [check_a_lost_line_is_a_device_error]


@dataclass
class ControlHarness:
    control: CameraControl
    cameras: list[str]
    ignore: Callable[[str], None]  # the camera stops applying what it is told
    silence: Callable[[], None]  # the device stops answering


VALUES: dict[str, float | str] = {"focus": 0.25, "exposure_us": 5000}


def check_one_result_per_camera_and_setting(h: ControlHarness) -> None:
    cams = h.cameras[:2]
    results = h.control.apply(VALUES, cams)
    assert sorted((r.camera, r.setting) for r in results) == sorted((c, s) for c in cams for s in VALUES)
    for r in results:
        assert r.requested == VALUES[r.setting]
        assert not r.state.is_problem, r
        # confirmed exactly when the path can read values back, and then with the value the camera reports
        assert (r.state is SettingState.CONFIRMED) == h.control.can_confirm, r
        if r.state is SettingState.CONFIRMED:
            assert r.reported is not None


def check_a_camera_that_ignores_is_never_confirmed(h: ControlHarness) -> None:
    deaf, fine = h.cameras[0], h.cameras[1]
    h.ignore(deaf)
    by = {r.camera: r for r in h.control.apply({"focus": 0.5}, [deaf, fine])}
    assert by[deaf].state is not SettingState.CONFIRMED
    if h.control.can_confirm:
        assert by[deaf].state is SettingState.MISMATCH and by[fine].state is SettingState.CONFIRMED
    else:
        assert by[deaf].state is SettingState.UNCONFIRMED  # nothing to compare with: not shown as applied


def check_an_unreachable_camera_is_a_failed_result(h: ControlHarness) -> None:
    h.silence()
    results = h.control.apply({"exposure_us": 5000}, h.cameras[:1])
    assert [r.state for r in results] == [SettingState.FAILED]
    assert results[0].detail


def check_control_close_is_quiet_and_repeatable(h: ControlHarness) -> None:
    h.control.close()
    h.control.close()


CONTROL_CONTRACT = [
    check_one_result_per_camera_and_setting,
    check_a_camera_that_ignores_is_never_confirmed,
    check_an_unreachable_camera_is_a_failed_result,
    check_control_close_is_quiet_and_repeatable,
]
