"""Tally over a real serial line: a pseudo-terminal pair, through pyserial and termios."""

from __future__ import annotations

import os
import select
import threading
from pathlib import Path

import pytest
import yaml
from rigctl.drivers.protocols import tsl31

from rigctl.errors import DeviceError
from rigctl.interfaces import TallyState
from rigctl.registry import open_tally
from rigctl.rig import load_rig

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def pty_line():  # type: ignore[no-untyped-def]
    """A fresh pty pair per test (a configured pty cannot be reopened with even parity)."""
    master, slave = os.openpty()
    path = os.ttyname(slave)
    yield master, path
    os.close(master)
    os.close(slave)


def read_all(fd: int, n: int, timeout: float = 5.0) -> bytes:
    out = b""
    while len(out) < n:
        r, _, _ = select.select([fd], [], [], timeout)
        if not r:
            break
        out += os.read(fd, 65536)
    return out


def rig_with_tally(tmp_path: Path, port: str, addresses: dict[str, int] | None = None) -> Path:
    rig = yaml.safe_load((REPO / "rigs" / "sim-3x3.yaml").read_text())
    rig["tally"] = {"protocol": "tsl-umd-3.1", "port": port}
    if addresses:
        rig["tally"]["addresses"] = addresses
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    return path


def test_rigctl_tally_sends_one_frame_per_camera(tmp_path: Path, pty_line, run_cli) -> None:  # type: ignore[no-untyped-def]
    master, port = pty_line
    rig = rig_with_tally(tmp_path, port, {"r2c2": 42})
    res = run_cli("tally", str(rig), "--program", "r1c1", "--preview", "r0c0", "r1c1")
    assert res.returncode == 0, res.stderr
    data = read_all(master, 9 * 18)
    assert len(data) == 9 * 18
    frames = [tsl31.decode(data[i : i + 18]) for i in range(0, len(data), 18)]
    names = load_rig(rig).camera_names
    assert [f.text for f in frames] == names
    assert [f.address for f in frames] == [1, 2, 3, 4, 5, 6, 7, 8, 42]
    by = {f.text: f for f in frames}
    assert by["r1c1"].tally[:2] == (True, True)  # tally 1 = preview, tally 2 = program
    assert by["r0c0"].tally[:2] == (True, False)
    assert all(f.tally == (False, False, False, False) for n, f in by.items() if n not in ("r0c0", "r1c1"))
    assert all(f.brightness == 3 for f in frames)
    assert data[:2] == bytes([0x81, 0x31])


def test_tsl31_addresses_end_at_126(tmp_path: Path, pty_line, run_cli) -> None:  # type: ignore[no-untyped-def]
    """The header byte is 0x80 + address, so 126 (0xFE) is the last address; 127 would be 0xFF, and TSL 5.0's
    wider display indexes do not apply to 3.1: refused in one line, before anything is on the line."""
    master, port = pty_line
    res = run_cli("tally", str(rig_with_tally(tmp_path, port, {"r0c0": 0, "r2c2": 126})), "--program", "r2c2")
    assert res.returncode == 0, res.stderr
    data = read_all(master, 9 * 18)
    assert data[0::18] == bytes([0x80, 0x82, 0x83, 0x84, 0x85, 0x86, 0x87, 0x88, 0xFE])
    assert data[-18:] == bytes([0xFE, 0x32]) + b"r2c2".ljust(16)  # program = tally 2, brightness 3
    rig = rig_with_tally(tmp_path, port, {"r2c2": 127})
    res = run_cli("tally", str(rig), "--program", "r2c2")
    assert res.returncode == 3
    assert res.stderr.strip().endswith("tally.addresses.r2c2 must be 0..126 for tsl-umd-3.1, got 127")
    assert len(res.stderr.splitlines()) == 1
    assert read_all(master, 1, timeout=0.3) == b""


def test_thousand_state_changes_arrive_in_order(tmp_path: Path, pty_line) -> None:  # type: ignore[no-untyped-def]
    master, port = pty_line
    rig = load_rig(rig_with_tally(tmp_path, port))
    out = open_tally(rig)
    names = rig.camera_names
    received: list[tsl31.Tsl31Message] = []
    expected = 1000 * 9 * 18

    def reader() -> None:
        dec = tsl31.Tsl31Decoder()
        got = 0
        while got < expected:
            r, _, _ = select.select([master], [], [], 10)
            if not r:
                return
            chunk = os.read(master, 65536)
            got += len(chunk)
            received.extend(dec.feed(chunk))

    t = threading.Thread(target=reader)
    t.start()
    try:
        for k in range(1000):
            out.send(TallyState(program=frozenset({names[k % 9]})))
    finally:
        t.join(timeout=30)
        out.close()
    assert len(received) == 9000
    programs = [m.text for m in received if m.tally[1]]
    assert programs == [names[k % 9] for k in range(1000)]


def test_port_is_exclusive_and_missing_port_is_named(tmp_path: Path, pty_line) -> None:  # type: ignore[no-untyped-def]
    _, port = pty_line
    rig = load_rig(rig_with_tally(tmp_path, port))
    first = open_tally(rig)
    try:
        with pytest.raises(DeviceError, match="busy"):
            open_tally(rig)
    finally:
        first.close()
    missing = load_rig(rig_with_tally(tmp_path, "/dev/ttyNOPE9"))
    with pytest.raises(DeviceError, match="/dev/ttyNOPE9: no such serial port"):
        open_tally(missing)


def test_line_settings_are_tsl_31(tmp_path: Path, pty_line) -> None:  # type: ignore[no-untyped-def]
    _, port = pty_line
    out = open_tally(load_rig(rig_with_tally(tmp_path, port)))
    try:
        link = out.link  # type: ignore[attr-defined]
        assert (link.baudrate, link.bytesize, link.parity, link.stopbits) == (38400, 8, "E", 1)
    finally:
        out.close()


def test_rig_without_tally_says_so(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    rig = yaml.safe_load((REPO / "rigs" / "sim-3x3.yaml").read_text())
    del rig["tally"]
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    res = run_cli("tally", str(path), "--program", "r1c1")
    assert res.returncode == 3 and "has no tally section" in res.stderr


def test_unplug_for_three_seconds_state_back_within_a_second_of_replug(tmp_path: Path) -> None:
    import time

    from rigctl.simulators.tsl_receiver import SimTslReceiver

    from rigctl.tally import TallyService

    link = tmp_path / "ttyTALLY"
    receiver = SimTslReceiver(link)
    rig = load_rig(rig_with_tally(tmp_path, str(link)))
    service = TallyService(lambda: open_tally(rig), port_path=str(link)).start()
    try:
        service.set(TallyState(program=frozenset({"r1c1"}), preview=frozenset({"r0c2"})))
        deadline = time.monotonic() + 5
        while len(receiver.since(0)) < 18 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(receiver.since(0)) >= 18
        receiver.unplug()
        time.sleep(3.0)
        replugged = time.monotonic()
        receiver.plug()
        deadline = time.monotonic() + 5
        while receiver.first_after(replugged) is None and time.monotonic() < deadline:
            time.sleep(0.02)
        first = receiver.first_after(replugged)
        assert first is not None and first - replugged < 1.0, "full state not back within 1 s of replug"
        time.sleep(0.3)
        frames = receiver.since(replugged)[:9]
        assert [f.text for f in frames] == rig.camera_names  # the whole state, every camera
        by = {f.text: f for f in frames}
        assert by["r1c1"].tally[1] and by["r0c2"].tally[0]
        assert service.connected
    finally:
        service.stop()
        receiver.close()
