"""Camera control, reference and tally outputs through real lines: the SDI bridge on a pseudo-terminal (real
pyserial and termios), TSL UMD 5.0 on a real UDP socket, USB identities through the real pyusb code path."""

from __future__ import annotations

import json
import socket
import struct
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from rigctl.drivers.bmd_camera_control import BmdBridgeControl
from rigctl.drivers.embedded_tally_output import EmbeddedTallyOutput
from rigctl.drivers.protocols import bmd_control, tsl50
from rigctl.drivers.sdi_bridge import SdiBridge
from rigctl.simulators.sdi_bridge import SimSdiBridge
from tally_support import TcpReceiver  # type: ignore[import-not-found]
from tests_support import make_non_device  # type: ignore[import-not-found]

from rigctl.errors import DeviceError
from rigctl.interfaces import CaptureFormat, SettingState, TallyState
from rigctl.pixfmt import luma
from rigctl.registry import open_cameras, open_control, open_tally
from rigctl.rig import load_rig

REPO = Path(__file__).resolve().parents[2]
IDS = {f"r{r}c{c}": 3 * r + c + 1 for r in range(3) for c in range(3)}


def write_rig(tmp_path: Path, **sections: object) -> Path:
    rig = yaml.safe_load((REPO / "rigs" / "sim-3x3.yaml").read_text())
    rig.update(sections)
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    return path


def mean_luma(cam, rig) -> float:  # type: ignore[no-untyped-def]
    frame = None
    while frame is None:
        frame = cam.read(2.0)
    img = np.frombuffer(frame.data, np.uint8).reshape(rig.height_px, -1)
    return float(luma(img, rig.model.format.pixel_format)[100:, :].mean())  # below the burnt-in ids


@pytest.mark.parametrize("blind", [False, True])
def test_exposure_through_the_bridge_changes_the_images(blind: bool) -> None:
    rig = load_rig("sim-3x3")
    devices = open_cameras(rig, ["noise=0", "motion=false"], ["r0c0", "r1c1", "r2c2"])
    cams = devices.cameras
    for cam in cams.values():
        cam.open()
        cam.configure(CaptureFormat(rig.width_px, rig.height_px, rig.model.format.pixel_format, rig.fps))
        cam.start()
    array = devices.simulation
    sim = SimSdiBridge(array, IDS, readback=not blind)
    control = BmdBridgeControl(SdiBridge(sim.port), IDS)
    try:
        before = {n: mean_luma(c, rig) for n, c in cams.items()}
        results = control.apply({"exposure_us": 10_000}, list(cams))
        after = {n: mean_luma(c, rig) for n, c in cams.items()}
    finally:
        control.close()
        sim.close()
        devices.close()
    # half the exposure: the picture above black (16) halves
    for n in cams:
        assert (after[n] - 16) == pytest.approx((before[n] - 16) / 2, rel=0.05), n
    assert {r.camera for r in results} == set(cams)
    assert {r.state for r in results} == {SettingState.UNCONFIRMED if blind else SettingState.CONFIRMED}
    assert all(r.reported == (None if blind else 10_000) for r in results)


def test_cli_control_confirms_and_reports_reference_lock(run_cli) -> None:  # type: ignore[no-untyped-def]
    res = run_cli("control", "--exposure-us", "8000", "--reference", "internal", "--camera", "r1c1", "--json")
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert [(r["setting"], r["state"], r["reported"]) for r in out["results"]] == [
        ("exposure_us", "confirmed", 8000),
        ("reference", "confirmed", "internal"),
    ]
    assert out["reference"] == {"r1c1": "internal (free-running)"}
    res = run_cli("control", "--reference", "external", "--sim", "unlocked=[r0c2]", "--json")
    locks = json.loads(res.stdout)["reference"]
    assert locks["r0c2"] == "external, NOT LOCKED" and locks["r0c0"] == "external, locked"


def test_cli_control_blind_bridge_is_unconfirmed(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    rig = write_rig(tmp_path, camera_control={"bridge": "sim://bridge?blind=1"})
    res = run_cli("control", str(rig), "--gain", "2", "--white-balance-k", "5600")
    assert res.returncode == 0, res.stderr
    assert "blind" in res.stdout
    rows = [line for line in res.stdout.splitlines() if line.startswith("r")]
    assert len(rows) == 9 and all(line.count("unconfirmed") == 2 for line in rows)
    assert "confirmed " not in res.stdout.replace("unconfirmed", "")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--exposure-us", "0"], "exposure_us must be within 1..1e+06 us, got 0"),
        (["--gain", "2.5"], "gain must be a whole number"),
        (["--exposure-us", "nan"], "exposure_us must be within"),
        ([], "no camera setting given"),
        (["--gain", "2", "--camera", "r9c9"], "camera 'r9c9' is not in rig sim-3x3"),
    ],
)
def test_cli_control_bad_input_is_one_line(run_cli, args: list[str], message: str) -> None:  # type: ignore[no-untyped-def]
    res = run_cli("control", *args)
    assert res.returncode == 2
    assert message in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_camera_that_ignores_a_setting_is_a_mismatch() -> None:
    sim = SimSdiBridge(None, IDS)
    sim.ignoring = {"r2c1"}
    control = BmdBridgeControl(SdiBridge(sim.port), IDS, confirm_timeout_s=0.2)
    try:
        results = control.apply({"focus": 0.25}, ["r0c0", "r2c1"])
    finally:
        control.close()
        sim.close()
    assert [(r.camera, r.state) for r in results] == [("r0c0", SettingState.CONFIRMED), ("r2c1", SettingState.MISMATCH)]


def test_retries_through_garbage_and_slow_replies_apply_once() -> None:
    sim = SimSdiBridge(None, IDS)
    bridge = SdiBridge(sim.port, reply_timeout_s=0.15)
    try:
        sim.garbage_before_reply = b"\xb5\x62\x01\xff\x00\x13junk"
        sim.reply_delay_s = 0.2  # longer than the reply timeout: the host sends again, same sequence number
        bridge.send_control([bmd_control.Message(1, 1, 5, bmd_control.INT32, bmd_control.OFFSET, (1000,))])
        assert bridge.retries >= 1
        assert len(sim.packets) == 1  # applied once although received more than once
        sim.reply_delay_s = 0.0
        back = bridge.query(1, 1, 5)
        assert back is not None and back.values == (1000,)
    finally:
        bridge.close()
        sim.close()


def test_silent_bridge_and_unplugged_bridge_fail_clearly() -> None:
    sim = SimSdiBridge(None, IDS)
    control = BmdBridgeControl(SdiBridge(sim.port, reply_timeout_s=0.1), IDS)
    try:
        sim.mute = True
        results = control.apply({"exposure_us": 5000}, ["r0c0"])
        assert results[0].state is SettingState.FAILED
        assert "no reply from the SDI bridge to CONTROL within 0.10 s (3 tries)" in results[0].detail
        sim.mute = False
        sim.unplug()
        results = control.apply({"exposure_us": 5000}, ["r0c0"])
        assert results[0].state is SettingState.FAILED and sim.port in results[0].detail
    finally:
        control.close()
        sim.close()
    with pytest.raises(DeviceError, match="no such serial port"):
        SdiBridge(str(REPO / "no-such-tty"))


def test_embedded_tally_through_the_bridge() -> None:
    sim = SimSdiBridge(None, IDS)
    out = EmbeddedTallyOutput(SdiBridge(sim.port), IDS)
    try:
        out.send(TallyState(program=frozenset({"r0c2"}), preview=frozenset({"r1c0"})))
    finally:
        out.close()
        sim.close()
    assert sim.tally is not None
    assert sim.tally.program == {3} and sim.tally.preview == {4}  # cameras numbered from 1


def test_sim_rig_tally_and_control_share_the_simulated_bridge(run_cli) -> None:  # type: ignore[no-untyped-def]
    res = run_cli("tally", "--program", "r1c1")
    assert res.returncode == 0, res.stderr
    rig = load_rig("sim-3x3")
    devices = open_cameras(rig, [], ["r0c0"])
    control = open_control(rig, devices)
    try:
        assert control.can_confirm and "sim://bridge" in control.description
    finally:
        control.close()
        devices.close()


def test_tsl50_over_udp(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(10)
    port = rx.getsockname()[1]
    rig = write_rig(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": f"udp://127.0.0.1:{port}"})
    try:
        res = run_cli("tally", str(rig), "--program", "r0c1", "--preview", "r2c2")
        assert res.returncode == 0, res.stderr
        packet = tsl50.decode(rx.recv(2048))
    finally:
        rx.close()
    assert [d.index for d in packet.displays] == list(range(1, 10))
    by = {d.text: d for d in packet.displays}
    assert by["r0c1"].left == by["r0c1"].right == tsl50.RED
    assert by["r2c2"].text_tally == tsl50.GREEN
    assert by["r0c0"].right == tsl50.OFF and by["r0c0"].brightness == 3


def udp_receiver() -> tuple[socket.socket, int]:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    return rx, rx.getsockname()[1]


def test_tsl50_indexes_past_126_go_out_byte_exact(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    """Display indexes TSL 3.1 cannot carry, on the wire as the spec lays them out: PBC, VER, FLAGS, SCREEN,
    then per camera INDEX, CONTROL, LENGTH, TEXT, 16-bit fields low byte first."""
    rx, port = udp_receiver()
    rx.settimeout(10)
    addresses = {"r0c0": 1000, "r1c1": 127, "r2c2": 65534}
    rig = write_rig(
        tmp_path, tally={"protocol": "tsl-umd-5.0", "port": f"udp://127.0.0.1:{port}", "addresses": addresses}
    )
    try:
        res = run_cli("tally", str(rig), "--program", "r0c0", "--preview", "r2c2")
        assert res.returncode == 0, res.stderr
        data = rx.recv(2048)
    finally:
        rx.close()
    # CONTROL: program lights right, text and left red (1 | 1 << 2 | 1 << 4) at brightness 3 (3 << 6) = 0xD5;
    # preview green (2 | 2 << 2 | 2 << 4 | 3 << 6) = 0xEA; off, brightness 3 = 0xC0
    off = "C0 00 04 00"
    expected = (
        "5E 00 00 00 00 00"  # PBC 94 = 4 header bytes + 9 displays of 10; VER 0, FLAGS 0, SCREEN 0
        " E8 03 D5 00 04 00 72 30 63 30"  # r0c0 at 1000 (0x03E8), program
        f" 02 00 {off} 72 30 63 31 03 00 {off} 72 30 63 32"  # r0c1, r0c2 at their defaults 2, 3
        f" 04 00 {off} 72 31 63 30 7F 00 {off} 72 31 63 31 06 00 {off} 72 31 63 32"  # r1c1 at 127
        f" 07 00 {off} 72 32 63 30 08 00 {off} 72 32 63 31"
        " FE FF EA 00 04 00 72 32 63 32"  # r2c2 at 65534 (0xFFFE), preview
    )
    assert data.hex(" ").upper() == expected


@pytest.mark.parametrize(
    ("address", "message"),
    [
        (
            65535,
            "tally.addresses.r2c2 is 65535, TSL UMD 5.0's broadcast index (every display of the screen): "
            "give r2c2 its own display, 0..65534",
        ),
        (65536, "tally.addresses.r2c2 must be 0..65534 for tsl-umd-5.0, got 65536"),
    ],
)
def test_tsl50_broadcast_and_past_16_bits_are_refused_before_sending(  # type: ignore[no-untyped-def]
    tmp_path: Path, run_cli, address: int, message: str
) -> None:
    """65535 is the spec's broadcast INDEX: a display message there would light every display of the screen
    with one camera's label and lamps, so no camera may have it; 65536 does not fit the 16-bit field."""
    rx, port = udp_receiver()
    rx.settimeout(0.5)
    rig = write_rig(
        tmp_path, tally={"protocol": "tsl-umd-5.0", "port": f"udp://127.0.0.1:{port}", "addresses": {"r2c2": address}}
    )
    try:
        res = run_cli("tally", str(rig), "--program", "r2c2")
        with pytest.raises(TimeoutError):
            rx.recv(2048)
    finally:
        rx.close()
    assert res.returncode == 3
    assert res.stderr.splitlines() == [f"rigctl tally: error: {rig}:{line_of(rig, f'r2c2: {address}')}: {message}"]


def line_of(path: Path, text: str) -> int:
    return next(i for i, ln in enumerate(path.read_text().splitlines(), 1) if ln.strip().startswith(text))


@pytest.mark.parametrize(
    ("port", "code", "said"),
    [
        ("/dev/ttyUSB0", 3, "write udp://HOST:PORT or tcp://HOST:PORT"),
        ("tcp://127.0.0.1:\u00b2", 3, "with a port 1..65535"),  # '²'.isdigit() is True; int('²') raised
        ("tcp://[127.0.0.1:47001", 3, "an IPv6 host as [ADDRESS]"),
        ("tcp://::1:47001", 3, "an IPv6 host as [ADDRESS]"),
        ("udp://a..b:47001", 4, "'a..b' is not a host name"),  # the resolver's IDNA encoding raised UnicodeError
        ("tcp://.:47001", 4, "'.' is not a host name"),
    ],
)
def test_tsl50_bad_port_is_one_line(tmp_path: Path, run_cli, port: str, code: int, said: str) -> None:  # type: ignore[no-untyped-def]
    rig = write_rig(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": port})
    res = run_cli("tally", str(rig), "--program", "r0c1")
    lines = res.stderr.strip().splitlines()
    assert res.returncode == code and len(lines) == 1 and said in lines[0], res.stderr


def test_tsl50_over_tcp(tmp_path: Path, run_cli) -> None:  # type: ignore[no-untyped-def]
    """``rigctl tally`` to a receiver on a real TCP connection: the packet arrives DLE/STX framed, whole; with
    nothing listening, one line naming the address and exit 4."""
    rx = TcpReceiver()
    try:
        rig = write_rig(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": f"tcp://127.0.0.1:{rx.port}"})
        res = run_cli("tally", str(rig), "--program", "r0c1", "--preview", "r2c2")
        assert res.returncode == 0, res.stderr
        deadline = time.monotonic() + 10
        while len(rx.latest) < 9 and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        rx.close()
    assert not rx.errors and sorted(d.index for d in rx.latest.values()) == list(range(1, 10))
    assert rx.latest["r0c1"].left == rx.latest["r0c1"].right == tsl50.RED
    assert rx.latest["r2c2"].text_tally == tsl50.GREEN and rx.latest["r0c0"].right == tsl50.OFF
    res = run_cli("tally", str(rig), "--program", "r0c1")  # the receiver is gone: connection refused
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 4 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert f"tcp://127.0.0.1:{rx.port}: cannot connect to the tally receiver" in lines[0]


@pytest.mark.parametrize("how", ["closes", "resets"])
def test_tsl50_over_tcp_to_a_receiver_that_drops_the_connection_at_once_fails(
    tmp_path: Path, run_cli, how: str
) -> None:  # type: ignore[no-untyped-def]
    """A receiver that accepts and at once closes (or resets) the connection did not show the tally: ``rigctl
    tally`` says so in one line and exits 4, not "tally sent" (a closed TCP connection takes a send without a
    word; the reset comes back after it)."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    stop = threading.Event()

    def drop() -> None:
        server.settimeout(0.05)
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            if how == "resets":
                conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            conn.close()

    thread = threading.Thread(target=drop, daemon=True)
    thread.start()
    try:
        rig = write_rig(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": f"tcp://127.0.0.1:{port}"})
        for _ in range(3):  # whichever comes first, the drop or the send
            res = run_cli("tally", str(rig), "--program", "r0c1")
            lines = res.stderr.strip().splitlines()
            assert res.returncode == 4 and len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
            # whichever moment it is seen at: on connecting, before sending, or in the wait after it
            said = (
                "Connection reset by peer",
                "the receiver closed the connection",
                "the receiver reset the connection",
            )
            assert f"tcp://127.0.0.1:{port}: " in lines[0] and any(w in lines[0] for w in said), lines[0]
            assert "tally sent" not in res.stdout
    finally:
        stop.set()
        thread.join(5)
        server.close()


def test_tsl50_tcp_receiver_restarted_gets_the_whole_state_back(tmp_path: Path) -> None:
    """The shoot's tally service on TCP: a receiver that reboots (connection reset, port closed for 2 s, then
    listening again) has every camera's lamps back within the service's backoff, nobody doing anything."""
    from rigctl.tally import TallyService

    rx = TcpReceiver()
    port = rx.port
    rig = load_rig(write_rig(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": f"tcp://127.0.0.1:{port}"}))
    service = TallyService(lambda: open_tally(rig)).start()
    state = TallyState(program=frozenset({"r1c1"}), preview=frozenset({"r0c2"}))

    def whole(receiver: TcpReceiver, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            got = dict(receiver.latest)
            if len(got) == 9 and got["r1c1"].left == tsl50.RED and got["r0c2"].left == tsl50.GREEN:
                return True
            time.sleep(0.02)
        return False

    try:
        service.set(state)
        assert whole(rx, 10) and service.connected
        rx.reset()
        rx.close()
        time.sleep(2.0)
        assert not service.connected and "tcp://127.0.0.1" in service.last_error
        rx = TcpReceiver(port)
        assert whole(rx, 15), "the state never came back after the receiver restarted"
        assert service.connected and rx.connections == 1 and not rx.errors
    finally:
        service.stop()
        rx.close()


FTDI = {"vendor_id": 0x0403, "product_id": 0x6001, "manufacturer": "FTDI", "product": "FT232R USB UART"}


def usb_env(tmp_path: Path) -> Path:
    devices = [
        {**FTDI, "serial": "TALLY01", "bus": 1, "ports": [2, 1]},
        {**FTDI, "serial": "BRIDGE01", "bus": 1, "ports": [2, 2]},
    ]
    path = tmp_path / "usb.yaml"
    path.write_text(yaml.safe_dump(devices))
    return path


def run_devices(tmp_path: Path, rig: Path) -> tuple[int, str, str]:
    import os
    import subprocess

    from tests_support import rigctl_exe

    env = {**os.environ, "RIGCTL_SIM_USB": str(usb_env(tmp_path))}
    res = subprocess.run([*rigctl_exe(), "devices", str(rig)], capture_output=True, text=True, env=env, timeout=60)
    return res.returncode, res.stdout, res.stderr


def test_devices_maps_usb_identities_onto_the_rig(tmp_path: Path) -> None:
    ident = {"vendor_id": 0x0403, "product_id": 0x6001}
    rig = write_rig(
        tmp_path,
        tally={"protocol": "tsl-umd-3.1", "port": "/dev/null", "usb": {**ident, "serial": "TALLY01"}},
        camera_control={"bridge": "sim://bridge", "usb": {**ident, "bus_path": "1-2.2"}},
    )
    code, out, err = run_devices(tmp_path, rig)
    assert code == 0, out + err
    assert "USB devices: 2" in out
    assert "USB identity of tally: 0403:6001 FTDI FT232R USB UART serial TALLY01 at 1-2.1" in out
    assert "USB identity of bridge: 0403:6001 FTDI FT232R USB UART serial BRIDGE01 at 1-2.2" in out


@pytest.mark.parametrize(
    ("usb", "message"),
    [
        ({}, "tally: 2 attached USB devices match 0403:6001"),
        ({"serial": "GONE"}, "tally: no attached USB device matches 0403:6001 serial GONE"),
    ],
)
def test_devices_names_ambiguous_or_missing_identity(tmp_path: Path, usb: dict[str, str], message: str) -> None:
    rig = write_rig(
        tmp_path,
        tally={
            "protocol": "tsl-umd-3.1",
            "port": "/dev/null",
            "usb": {"vendor_id": 0x0403, "product_id": 0x6001, **usb},
        },
    )
    code, out, _ = run_devices(tmp_path, rig)
    assert code == 1
    assert message in out


@pytest.mark.parametrize("kind", ["a folder", "a file", "a FIFO"])
def test_devices_does_not_call_a_line_found_that_is_no_device(tmp_path: Path, kind: str) -> None:
    """A hostile-user review: a tally port that is a folder, a file or a FIFO was "found" (exit 0), which
    rigctl tally then refuses; a device node (a pty, /dev/null) still is found."""
    import os

    port = make_non_device(tmp_path / "port", kind)
    master, slave = os.openpty()
    tty = os.ttyname(slave)
    try:
        rig = write_rig(tmp_path, tally={"protocol": "tsl-umd-3.1", "port": str(port)}, camera_control={"bridge": tty})
        code, out, err = run_devices(tmp_path, rig)
    finally:
        os.close(master)
        os.close(slave)
    assert code == 1, out + err
    assert f"tally: {port}  MISSING" in out and f"bridge: {tty}  found" in out
    assert f"tally line ({port}: exists but is {kind}, not a device)" in out.splitlines()[-1]


def test_a_new_host_session_is_not_taken_for_a_retry() -> None:
    sim = SimSdiBridge(None, IDS)
    try:
        for exposure in (1000, 2000):  # both sessions send HELLO (0) then CONTROL (1)
            bridge = SdiBridge(sim.port)
            bridge.send_control([bmd_control.Message(1, 1, 5, bmd_control.INT32, bmd_control.ASSIGN, (exposure,))])
            bridge.close()
        assert len(sim.packets) == 2 and sim.state["r0c0"][(1, 5)] == (2000,)
    finally:
        sim.close()


def test_a_line_that_answers_in_something_else_than_bridge_frames_is_not_called_silent() -> None:
    """Another device on the port (or another baud rate) answers every frame with bytes of its own: that is
    said, not 'no reply', which sends the crew to look for a dead bridge."""
    import os
    import threading

    master, slave = os.openpty()
    stop = threading.Event()

    def chatter() -> None:
        while not stop.is_set():
            try:
                if os.read(master, 256):
                    os.write(master, b"OK\r\nERROR 17\r\n" * 4)
            except OSError:
                return

    talker = threading.Thread(target=chatter, daemon=True)
    talker.start()
    try:
        with pytest.raises(DeviceError) as caught:
            SdiBridge(os.ttyname(slave), reply_timeout_s=0.1)
        text = str(caught.value)
        assert "no bridge frame in what the line sent back to HELLO" in text and "no reply" not in text, text
        assert "bytes of something else in 3 tries" in text and "baud rate" in text
    finally:
        stop.set()
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize(
    ("port", "said"),
    [
        ("tcp://a..b:47001", "'a..b' is not a host name"),
        ("tcp://127.0.0.1:99999", "with a port 1..65535"),
        ("tcp://::1:47001", "an IPv6 host as [ADDRESS]"),
        ("socket://127.0.0.1:47001", "write udp://HOST:PORT or tcp://HOST:PORT"),  # a serial line's URL
    ],
)
def test_devices_names_a_tally_url_that_rigctl_tally_refuses(tmp_path: Path, port: str, said: str) -> None:
    """A hostile-user review: ``rigctl devices`` called any network tally address "network" (exit 0) that
    ``rigctl tally`` then refused; such an address is now INVALID, named with the reason, exit 1. A good one
    stays "network" (nothing is sent to find out whether a receiver answers)."""
    rig = write_rig(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": port})
    code, out, err = run_devices(tmp_path, rig)
    assert code == 1 and "Traceback" not in err, out + err
    assert f"tally: {port}  INVALID" in out and said in out.split("missing:")[1], out
    good = write_rig(tmp_path, tally={"protocol": "tsl-umd-5.0", "port": "tcp://[::1]:47001"})
    code, out, err = run_devices(tmp_path, good)
    assert code == 0 and "tally: tcp://[::1]:47001  network" in out, out + err
