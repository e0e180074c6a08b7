"""Device addresses are parsed once, into a scheme the registry's factory tables know, or refused with one
line naming the device's role."""

from __future__ import annotations

import pytest

from rigctl.address import camera_address, line_address
from rigctl.errors import DeviceError
from rigctl.registry import CAMERA_FACTORIES, open_cameras
from rigctl.rig import load_rig, rig_from_dict


@pytest.mark.parametrize(
    ("text", "scheme", "target"),
    [
        ("sim://r0c0", "sim", "r0c0"),
        ("v4l2:///dev/video3", "v4l2", "/dev/video3"),
        ("/dev/video0", "v4l2", "/dev/video0"),
        ("/dev/v4l/by-id/usb-x-video-index0", "v4l2", "/dev/v4l/by-id/usb-x-video-index0"),
    ],
)
def test_camera_addresses(text: str, scheme: str, target: str) -> None:
    a = camera_address(text, "r0c0")
    assert (a.scheme, a.target, a.text) == (scheme, target, text)
    assert a.scheme in CAMERA_FACTORIES


@pytest.mark.parametrize(
    ("text", "scheme"),
    [
        ("/dev/ttyUSB0", "serial"),
        ("sim://bridge?blind=1", "sim"),
        ("loop://", "loop"),
        ("spy:///dev/ttyUSB0", "spy"),
        ("udp://10.0.0.5:8900", "udp"),
        ("tcp://10.0.0.5:9000", "tcp"),
        ("RFC2217://host:2217", "rfc2217"),
    ],
)
def test_line_addresses(text: str, scheme: str) -> None:
    assert line_address(text, "tally port").scheme == scheme


def test_query_options_are_parsed_once() -> None:
    a = line_address("sim://bridge?blind=1&x=", "bridge")
    assert (a.target, a.options, a.base) == ("bridge", {"blind": "1", "x": ""}, "sim://bridge")


@pytest.mark.parametrize(
    ("text", "why"),
    [
        ("foo://bar", "unknown scheme"),
        ("http://camera.local/stream", "unknown scheme"),
        ("video0", "unknown scheme"),
        ("v4l2://dev/video0", "absolute path"),
        ("sim://", "names no device"),
        # a simulated camera is the camera of the rig it names, never a path or another camera (a hostile-user
        # review: rigctl devices called sim://../../x a simulated camera, which record refused)
        ("sim://../../x", "'sim://../../x': a simulated camera is sim://r2c1"),
        ("sim:///dev/video0", "a simulated camera is sim://r2c1"),
        ("sim://r0c0", "a simulated camera is sim://r2c1"),
        ("sim://bridge", "a simulated camera is sim://r2c1"),
        ("", "empty"),
        ("   ", "empty"),
    ],
)
def test_bad_camera_addresses_name_the_camera(text: str, why: str) -> None:
    with pytest.raises(DeviceError, match=f"camera r2c1: .*{why}"):
        camera_address(text, "r2c1")


@pytest.mark.parametrize("text", ["sim://../../x", "sim://r0c0", "sim://bridge/../x"])
def test_the_one_simulated_line_is_the_bridge(text: str) -> None:
    with pytest.raises(DeviceError, match=f"tally port: device address '{text}': the simulated line is sim://bridge"):
        line_address(text, "tally port")


def test_a_line_scheme_is_not_a_camera() -> None:
    with pytest.raises(DeviceError, match=r"camera r0c0: device address 'udp://h:1': unknown scheme"):
        camera_address("udp://h:1", "r0c0")
    with pytest.raises(DeviceError, match=r"tally port: .*unknown scheme"):
        line_address("v4l2:///dev/video0", "tally port")


def test_open_cameras_refuses_a_rig_with_an_unknown_scheme_naming_the_camera() -> None:
    data = load_rig("sim-3x3").to_dict()
    data["cameras"][4]["device"] = "foo://bar"
    with pytest.raises(DeviceError, match=r"camera r1c1: device address 'foo://bar'"):
        open_cameras(rig_from_dict(data))


def test_open_cameras_keeps_the_rig_order_and_hands_the_simulation_over() -> None:
    rig = load_rig("sim-3x3")
    devices = open_cameras(rig, ["noise=0"], ["r2c2", "r0c0"])
    try:
        assert list(devices.cameras) == ["r0c0", "r2c2"]
        assert devices.simulation is not None and devices.truth is not None
    finally:
        devices.close()
