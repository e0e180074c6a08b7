"""The tally and camera-control contracts against every driver, each opened from a rig file through the
registry as a user's rig opens it, on a real line with a simulated device at the far end:

- TSL UMD 3.1 on a pseudo-terminal (pyserial and termios) to a simulated receiver;
- TSL UMD 5.0 on a UDP socket, and on a TCP connection (DLE/STX framed) that the receiver can reset;
- embedded tally and Blackmagic camera control through the SDI bridge driver on a pseudo-terminal to the
  simulated bridge, with read-back and blind.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import yaml
from line_contract import (  # type: ignore[import-not-found]
    CONTROL_CONTRACT,
    TALLY_CONTRACT,
    TALLY_LINE_CONTRACT,
    ControlHarness,
    Lamps,
    TallyHarness,
)
from rigctl.drivers.protocols import tsl50
from rigctl.simulators.sdi_bridge import SimSdiBridge
from rigctl.simulators.tsl_receiver import SimTslReceiver
from tally_support import TcpReceiver  # type: ignore[import-not-found]

from rigctl.camera_control import camera_ids
from rigctl.registry import open_control, open_tally
from rigctl.rig import Rig, load_rig

REPO = Path(__file__).resolve().parents[2]


def rig_file(tmp_path: Path, **sections: object) -> Rig:
    data = yaml.safe_load((REPO / "rigs" / "sim-3x3.yaml").read_text())
    data.update(sections)
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_rig(path)


def tsl31_pty(tmp_path: Path) -> tuple[TallyHarness, Callable[[], None]]:
    receiver = SimTslReceiver(tmp_path / "ttyTALLY")
    rig = rig_file(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": str(tmp_path / "ttyTALLY")})

    def received() -> Lamps | None:
        latest: Lamps = {}
        for m in receiver.since(0.0):
            latest[m.text] = (m.tally[1], m.tally[0])  # tally 2 is program, tally 1 preview
        return latest if set(latest) == set(rig.camera_names) else None

    return TallyHarness(open_tally(rig), rig.camera_names, received, receiver.unplug), receiver.close


def tsl50_udp(tmp_path: Path) -> tuple[TallyHarness, Callable[[], None]]:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    rig = rig_file(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": f"udp://127.0.0.1:{rx.getsockname()[1]}"})
    latest: Lamps = {}

    def received() -> Lamps | None:
        while True:
            try:
                packet = tsl50.decode(rx.recv(65536))
            except BlockingIOError:
                break
            for d in packet.displays:
                latest[d.text] = (d.left == tsl50.RED, d.left == tsl50.GREEN)
        return dict(latest) if set(latest) == set(rig.camera_names) else None

    return TallyHarness(open_tally(rig), rig.camera_names, received, None), rx.close


def tsl50_tcp(tmp_path: Path) -> tuple[TallyHarness, Callable[[], None]]:
    rx = TcpReceiver()
    rig = rig_file(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": f"tcp://127.0.0.1:{rx.port}"})

    def received() -> Lamps | None:
        assert not rx.errors, rx.errors  # every byte on the stream framed as TSL says
        latest = {n: (d.left == tsl50.RED, d.left == tsl50.GREEN) for n, d in rx.latest.items()}
        return latest if set(latest) == set(rig.camera_names) else None

    return TallyHarness(open_tally(rig), rig.camera_names, received, rx.reset), rx.close


def embedded_bridge(tmp_path: Path) -> tuple[TallyHarness, Callable[[], None]]:
    rig = rig_file(tmp_path)
    ids = camera_ids(rig)
    sim = SimSdiBridge(None, ids)
    rig = rig_file(tmp_path, tally={"protocol": "bmd-embedded", "port": sim.port})
    names = {i: n for n, i in ids.items()}

    def received() -> Lamps | None:
        t = sim.tally
        if t is None:
            return None
        return {n: (i in t.program, i in t.preview) for i, n in names.items()}

    return TallyHarness(open_tally(rig), rig.camera_names, received, sim.unplug), sim.close


TALLY_LINES = {
    "tsl31-pty": tsl31_pty,
    "tsl50-udp": tsl50_udp,
    "tsl50-tcp": tsl50_tcp,
    "embedded-bridge-pty": embedded_bridge,
}
CASES = [(name, check) for name in TALLY_LINES for check in TALLY_CONTRACT] + [
    (name, check) for name in ("tsl31-pty", "tsl50-tcp", "embedded-bridge-pty") for check in TALLY_LINE_CONTRACT
]


@pytest.mark.parametrize(("line", "check"), CASES, ids=[f"{n}-{c.__name__}" for n, c in CASES])
def test_tally_contract(line: str, check: Callable[[TallyHarness], None], tmp_path: Path) -> None:
    harness, stop = TALLY_LINES[line](tmp_path)
    try:
        check(harness)
    finally:
        harness.output.close()
        stop()


@pytest.fixture(params=[True, False], ids=["bridge-reads-back", "bridge-blind"])
def control(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ControlHarness]:
    rig = rig_file(tmp_path)
    sim = SimSdiBridge(None, camera_ids(rig), readback=request.param)
    rig = rig_file(tmp_path, camera_control={"bridge": sim.port})
    ctl = open_control(rig)
    ctl.confirm_timeout_s = 0.5  # type: ignore[attr-defined]
    ctl.bridge.reply_timeout_s = 0.2  # type: ignore[attr-defined]  # the silenced bridge's three tries

    def silence() -> None:
        sim.mute = True

    harness = ControlHarness(ctl, rig.camera_names, sim.ignoring.add, silence)
    try:
        yield harness
    finally:
        ctl.close()
        sim.close()


@pytest.mark.parametrize("check", CONTROL_CONTRACT, ids=[c.__name__ for c in CONTROL_CONTRACT])
def test_camera_control_contract(check: Callable[[ControlHarness], None], control: ControlHarness) -> None:
    assert control.control.can_confirm == ("blind" not in control.control.description)
    check(control)
