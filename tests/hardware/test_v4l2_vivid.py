"""The V4L2 driver on real kernel devices (vivid in CI): the camera contract, formats, timings, drops,
busy and vanishing devices, and a 10 s take from nine devices."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from camera_contract import CONTRACT  # type: ignore[import-not-found]
from rigctl.drivers.v4l2.camera import V4L2Camera
from rigctl.drivers.v4l2.device import V4L2Device

from rigctl.errors import DeviceError
from rigctl.interfaces import CaptureFormat

FMT = CaptureFormat(1920, 1080, "UYVY", 25.0)
REPO = Path(__file__).resolve().parents[2]


def rigctl(*argv: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    exe = Path(sys.executable).with_name("rigctl")
    return subprocess.run([str(exe), *argv], capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)


@pytest.mark.parametrize("check", CONTRACT, ids=[c.__name__ for c in CONTRACT])
def test_contract_on_vivid(check, v4l2_devices) -> None:  # type: ignore[no-untyped-def]
    check(lambda: (V4L2Camera("r0c0", "v4l2://" + v4l2_devices[0]), FMT))


def test_format_negotiation_and_dv_timings(v4l2_devices) -> None:  # type: ignore[no-untyped-def]
    cam = V4L2Camera("r0c0", v4l2_devices[0])
    cam.open()
    try:
        got = cam.configure(FMT)
        assert got == FMT
        dev = cam.device
        assert dev.get_format()[:3] == (1920, 1080, "UYVY")
        t = dev.dv_timings()
        assert (t.width, t.height) == (1920, 1080) and t.fps == pytest.approx(25.0, abs=0.01)
        offered = dev.formats()
        assert "UYVY" in offered and len(offered) > 5
        with pytest.raises(DeviceError, match=r"pixel format H264 not offered \(offered: .*UYVY"):
            dev.set_format(1920, 1080, "H264")
        with pytest.raises(DeviceError, match=r"DV timings 1000x700p25 not offered \(offered: .*1920x1080p25"):
            cam.configure(CaptureFormat(1000, 700, "UYVY", 25.0))
        identity = dev.identity()
        assert identity["driver"] == "vivid"
    finally:
        cam.close()


def test_sequence_timestamps_and_stall_drops(v4l2_devices) -> None:  # type: ignore[no-untyped-def]
    cam = V4L2Camera("r0c0", v4l2_devices[0], buffers=4)
    cam.open()
    try:
        cam.configure(FMT)
        cam.start()
        buf = memoryview(bytearray(FMT.bytes_per_frame))
        frames = [cam.read(3.0, buf) for _ in range(10)]
        assert all(f is not None for f in frames)
        seqs = [f.sequence for f in frames]  # type: ignore[union-attr]
        caps = [f.capture_ns for f in frames]  # type: ignore[union-attr]
        assert all(b > a for a, b in itertools.pairwise(seqs))
        assert all(b > a for a, b in itertools.pairwise(caps))
        assert -40e6 < time.monotonic_ns() - caps[-1] < 5e9  # CLOCK_MONOTONIC (vivid stamps a bit ahead)
        before = cam.status().source_drops
        time.sleep(1.5)  # stall: the driver fills its 4 buffers, then has nowhere to put frames
        after = [cam.read(3.0, buf) for _ in range(6)]
        seq_after = [f.sequence for f in after if f is not None]
        gap = seq_after[-1] - seqs[-1] - len(seq_after)
        assert gap >= 10, f"a 1.5 s stall at 25 fps with 4 buffers loses frames; sequence gap {gap}"
        assert cam.status().source_drops - before == gap  # counted exactly as the driver numbered them
    finally:
        cam.close()


def test_busy_when_another_process_streams(v4l2_devices) -> None:  # type: ignore[no-untyped-def]
    dev = v4l2_devices[1]
    holder = subprocess.Popen(
        ["v4l2-ctl", "-d", dev, "--stream-mmap", "--stream-count=400"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        time.sleep(1.5)
        cam = V4L2Camera("r0c1", dev)
        cam.open()
        try:
            with pytest.raises(DeviceError, match="busy"):
                cam.configure(FMT)
        finally:
            cam.close()
    finally:
        holder.kill()
        holder.wait()
    # and two rigctl users exclude each other at open
    a, b = V4L2Camera("a", dev), V4L2Camera("b", dev)
    a.open()
    try:
        with pytest.raises(DeviceError, match="busy"):
            b.open()
    finally:
        a.close()


def test_missing_device_is_named(v4l2_devices) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(DeviceError, match="/dev/video99: no such device"):
        V4L2Device("v4l2:///dev/video99").open()


def _ctrl(dev: str, **controls: int) -> None:
    args = ",".join(f"{k}={v}" for k, v in controls.items())
    subprocess.run(["v4l2-ctl", "-d", dev, "-c", args], check=True, capture_output=True)


def _rig(tmp_path: Path, devices: list[str]) -> Path:
    rig = yaml.safe_load((REPO / "rigs" / "bmd-micro-studio-4k-3x3.yaml").read_text())
    rig["name"] = "vivid-3x3"
    rig["format"].update(width_px=1920, height_px=1080, fps=25)
    for section in ("tally", "camera_control"):  # the VM has the capture devices only, no serial lines
        rig.pop(section, None)
    for cam, dev in zip(rig["cameras"], devices, strict=True):
        cam["device"] = f"v4l2://{dev}"
    path = tmp_path / "vivid.yaml"
    path.write_text(yaml.safe_dump(rig))
    return path


def test_ten_second_take_from_nine_devices(v4l2_devices, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    assert len(v4l2_devices) >= 9
    rig = _rig(tmp_path, v4l2_devices[:9])
    out = Path(os.environ.get("RIGCTL_TAKE_DIR", tmp_path))
    res = rigctl(
        "record",
        str(rig),
        "--take",
        "vivid10",
        "--seconds",
        "10",
        "--out",
        str(out),
        "--force",
        "--no-checksum",
        "--buffers",
        "4",
        "--json",
    )
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    take = out / "vivid10"
    man = yaml.safe_load((take / "take.yaml").read_text())
    assert man["status"] == "complete"
    assert set(man["cameras"]) == {f"r{r}c{c}" for r in range(3) for c in range(3)}
    for name, cam in man["cameras"].items():
        assert cam["frames"] >= 20, f"{name}: only {cam['frames']} frames in 10 s"
        # every frame slot of the 10 s (250 at 25 fps) is accounted for: stored, or a drop the driver's
        # sequence numbers show (drops just before the first or after the last stored frame included)
        first, last = cam["first_sequence"], cam["last_sequence"]
        lost_seqs = cam["source_drops"] + cam["writer_drops"] + cam["error_frames"]
        inside = [s for s in lost_seqs if first <= s <= last]
        assert cam["frames"] + len(inside) == last - first + 1, name
        assert len(set(lost_seqs)) == len(lost_seqs), f"{name}: a frame counted as lost twice"
        assert abs(cam["frames"] + len(lost_seqs) - 250) <= 3, (name, cam["frames"], len(lost_seqs))
    assert man["frame_sets"]["count"] >= 20
    skew = man["frame_sets"]["skew"]
    assert skew["sets"] > 0 and skew["p99_us"] >= skew["p50_us"] >= 0
    assert summary["frame_sets"] == man["frame_sets"]["count"]
    check = rigctl("take", "check", str(take), "--quick")
    assert check.returncode == 0, check.stderr
    # the bytes are vivid's own test pattern, in order: timestamps strictly increase in every index
    from rigctl.take.reader import TakeReader

    reader = TakeReader(take)
    for name in reader.names:
        cap = reader.index[name]["capture_ns"].astype(np.int64)
        assert np.all(np.diff(cap) > 0)
        frame = reader.frame_bytes(name, 0)
        assert frame.size == FMT.bytes_per_frame and frame.std() > 5  # a picture, not a blank buffer


def test_vanishing_device_ends_its_stream_while_others_record(v4l2_devices, tmp_path: Path, caplog) -> None:  # type: ignore[no-untyped-def]
    from rigctl.capture.recorder import Recorder, TakePlan
    from rigctl.registry import open_cameras
    from rigctl.rig import load_rig

    rig = load_rig(_rig(tmp_path, v4l2_devices[:9]))
    out = Path(os.environ.get("RIGCTL_TAKE_DIR", tmp_path))
    names = ["r0c0", "r1c1", "r2c2"]
    devices = open_cameras(rig, cameras=names)
    rec = Recorder(rig, devices, TakePlan.spread("vanish", [out], names), buffers_per_camera=4, checksum=False)
    rec.arm()
    rec.start(250)  # 10 s: starting v4l2-ctl alone takes seconds on an emulated CPU
    time.sleep(1.0)
    # vivid's "Disconnect" control emulates unplugging: the node then fails every ioctl with ENODEV
    _ctrl(v4l2_devices[4], disconnect=1)
    assert rec.wait(timeout_s=60)
    man = rec.finish()
    assert man is not None
    lost = man.cameras["r1c1"]
    assert "disappeared" in (lost.ended_early or ""), lost
    assert any("r1c1" in r.getMessage() and "disappeared" in r.getMessage() for r in caplog.records)
    others = [man.cameras[n] for n in ("r0c0", "r2c2")]
    assert all(c.frames > lost.frames for c in others)
    slots = [c.frames + len(c.source_drops) + len(c.writer_drops) + len(c.error_frames) for c in others]
    assert all(n >= 245 for n in slots), (slots, [c.frames for c in others], man.end)


def test_devices_lists_vivid_and_maps_the_rig(v4l2_devices, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from rigctl.discovery import describe_attached
    from rigctl.rig import load_rig

    found = describe_attached(load_rig(_rig(tmp_path, v4l2_devices[:9])))
    paths = {d["path"]: d for d in found["v4l2"]}
    for dev in v4l2_devices[:9]:
        assert paths[dev]["driver"] == "vivid" and "UYVY" in paths[dev]["formats"]
        assert paths[dev]["signal"].startswith("1920x1080p")
    assert all(c["state"] == "found" for c in found["cameras"]) and found["missing"] == []


def test_no_signal_refuses_to_arm_and_a_signal_change_is_recorded(v4l2_devices, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from rigctl.capture.recorder import Recorder, TakePlan
    from rigctl.registry import open_cameras
    from rigctl.rig import load_rig

    rig = load_rig(_rig(tmp_path, v4l2_devices[:9]))
    dev = v4l2_devices[7]
    _ctrl(dev, dv_timings_signal_mode=1)  # vivid: no signal at the input
    try:
        devices = open_cameras(rig, cameras=["r2c1"])
        rec = Recorder(rig, devices, TakePlan.spread("nosig", [tmp_path], ["r2c1"]), buffers_per_camera=4)
        with pytest.raises(DeviceError, match=r"no signal on r2c1 \(v4l2:///dev/video7\)"):
            rec.arm()
    finally:
        _ctrl(dev, dv_timings_signal_mode=0)
    devices = open_cameras(rig, cameras=["r2c1"])
    rec = Recorder(rig, devices, TakePlan.spread("change", [tmp_path], ["r2c1"]), buffers_per_camera=4, checksum=False)
    rec.arm()
    rec.start(150)
    time.sleep(2.0)
    # the source switches to another format mid-take (vivid: "selected" timings, index 0 is 640x480p60)
    _ctrl(dev, dv_timings=0, dv_timings_signal_mode=4)
    try:
        assert rec.wait(timeout_s=60)
        man = rec.finish()
    finally:
        _ctrl(dev, dv_timings_signal_mode=0)
    assert man is not None
    cam = man.cameras["r2c1"]
    assert cam.format_changed_at, cam  # recorded, and the take went on
    assert man.status == "complete" and cam.frames > 20
