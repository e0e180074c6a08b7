"""A careless or hostile user at ``rigctl record`` and at device addresses: each case is refused in one line with
the documented exit status, before anything is allocated or opened, and leaves nothing behind."""

from __future__ import annotations

import hashlib
import signal
import subprocess
import time
from pathlib import Path

import pytest
from hostile_support import SIM_RIG, one_line, write_yaml  # type: ignore[import-not-found]
from tests_support import rigctl_exe  # type: ignore[import-not-found]

from rigctl.errors import EXIT_BAD_INPUT, EXIT_DEVICE, EXIT_USAGE
from rigctl.take.check import check_take
from rigctl.take.index import RECORD_SIZE

DET = ["--sim", "deterministic=true", "--sim", "motion=false"]


def test_buffers_beyond_memory_are_refused_before_allocating(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    # it was an ENOMEM traceback from the frame pool's mmap, after the cameras had streamed
    for n in ("999999999", "1", "1025"):
        res = run_cli("record", "--take", "t", "--frames", "2", "--out", "takes", "--buffers", n, *DET)
        one_line(res, EXIT_USAGE, "--buffers must be 2 to ", f"got {n}")
    assert not (tmp_path / "takes").exists()


def test_a_sim_fault_for_a_camera_not_in_the_rig_is_refused(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    # it was accepted, recorded a take and injected nothing
    res = run_cli("record", "--take", "t", "--frames", "2", "--out", "takes", "--sim", "drops.r9c9=[0]", *DET)
    one_line(res, EXIT_USAGE, "--sim drops.r9c9: rig sim-3x3 has no camera r9c9 (its cameras: r0c0,", "r2c2)")
    assert not (tmp_path / "takes").exists()


@pytest.mark.parametrize("device", ["sim://../../x", "sim:///dev/video0", "sim://r2c2/../r2c2"])
def test_a_simulated_camera_address_that_is_not_the_camera_is_refused_alike(
    run_cli, tmp_path: Path, device: str
) -> None:  # type: ignore[no-untyped-def]
    # rigctl devices called sim://../../x a simulated camera (exit 0) where record refused it
    cameras = [dict(c) for c in SIM_RIG["cameras"]]
    cameras[8]["device"] = device
    rig = str(write_yaml(tmp_path / "rig.yaml", {**SIM_RIG, "cameras": cameras}))
    expected = f"camera r2c2: device address '{device}': a simulated camera is sim://r2c2"
    assert one_line(run_cli("devices", rig), EXIT_DEVICE, expected) == f"rigctl devices: error: {expected}"
    one_line(run_cli("devices", rig, "--json"), EXIT_DEVICE, expected)
    record = run_cli("record", rig, "--take", "t", "--frames", "1", "--out", "takes", *DET)
    assert one_line(record, EXIT_DEVICE, expected) == f"rigctl record: error: {expected}"
    assert not (tmp_path / "takes").exists()


def test_a_simulated_line_that_is_not_the_bridge_is_refused(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    rig = str(
        write_yaml(tmp_path / "rig.yaml", {**SIM_RIG, "tally": {"protocol": "bmd-embedded", "port": "sim://../x"}})
    )
    one_line(
        run_cli("devices", rig),
        EXIT_DEVICE,
        "tally line: device address 'sim://../x': the simulated line is sim://bridge",
    )


def _contents(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.rglob("*")
            if p.is_file()}  # fmt: skip


def test_a_recording_killed_mid_take_is_never_published_by_the_next_nor_lost(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """A recorder SIGKILLed mid-take leaves its frames under the hidden name. The same command run again used to
    publish them under the name as if they were the take, then exit 3 (the name taken). Now it is refused in one
    line naming the leftover and what to do, and touches no byte of it; another take name records beside it,
    naming it in a warning; renamed to its name by the user, it reads as the cut-off take it is."""
    proc = subprocess.Popen(
        [*rigctl_exe(), "record", "--take", "t", "--frames", "400", "--out", "takes", "--force", *DET[2:]],
        cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    staged = tmp_path / "takes" / ".t.rigctl-recording"
    index = staged / "cameras" / "r2c2.index"
    deadline = time.monotonic() + 60
    while not (index.exists() and index.stat().st_size >= 5 * RECORD_SIZE):  # frames on disk, the take far from over
        if time.monotonic() > deadline or proc.poll() is not None:
            proc.kill()
            pytest.fail(f"recording did not get going: {proc.communicate(timeout=10)[1].decode()[-2000:]}")
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    assert proc.wait(timeout=10) == -signal.SIGKILL
    proc.communicate(timeout=10)
    before = _contents(staged)
    assert any(k.endswith(".essence") for k in before)

    res = run_cli("record", "--take", "t", "--frames", "2", "--out", "takes", *DET)
    line = one_line(res, EXIT_BAD_INPUT, "takes/.t.rigctl-recording: a recording of t that was cut off (")
    assert "status: recording" in line and "rigctl take check takes/.t.rigctl-recording" in line, line
    assert "rename it to takes/t to keep it as that take, or remove it" in line, line
    assert sorted(p.name for p in (tmp_path / "takes").iterdir()) == [".t.rigctl-recording"]
    assert _contents(staged) == before

    res = run_cli("record", "--take", "u", "--frames", "2", "--out", "takes", *DET)
    assert res.returncode == 0, res.stderr
    assert len([ln for ln in res.stderr.splitlines() if "a recording of t that was cut off" in ln]) == 1, res.stderr
    assert sorted(p.name for p in (tmp_path / "takes").iterdir()) == [".t.rigctl-recording", "u"]
    assert _contents(staged) == before and check_take(tmp_path / "takes" / "u").ok

    staged.rename(tmp_path / "takes" / "t")  # what the line says to do to keep it
    assert check_take(tmp_path / "takes" / "t").ok


@pytest.mark.parametrize(
    ("camera", "extra", "code", "said"),
    [  # a camera that is not there (found when arming, after preflight made the destinations)
        ("v4l2:///dev/video99", ["--frames", "2"], EXIT_DEVICE, "v4l2:///dev/video99: no such device"),
        # preflight's refusal (it measured the destinations' speed in them)
        ("sim://r2c2", ["--seconds", "100000", *DET], EXIT_USAGE, "the take needs 1666.7 min"),
    ],
)
def test_a_record_that_fails_leaves_no_folder_it_made(  # type: ignore[no-untyped-def]
    run_cli, tmp_path: Path, camera: str, extra: list[str], code: int, said: str
) -> None:
    """It left empty --out and --dest folders behind (and their parents), for the user to find and clear."""
    cameras = [dict(c) for c in SIM_RIG["cameras"]]
    cameras[8]["device"] = camera
    rig = str(write_yaml(tmp_path / "rig.yaml", {**SIM_RIG, "cameras": cameras}))
    (tmp_path / "mine").mkdir()  # the user's: stays
    argv = ["record", rig, "--take", "t", "--out", "a/b", "--dest", "c", "--dest", "mine/d", *extra]
    res = run_cli(*argv)
    assert res.returncode == code and said in res.stderr.splitlines()[-1], res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "rig.yaml"]
    assert list((tmp_path / "mine").iterdir()) == []


def test_a_device_address_holding_a_nul_is_refused_in_one_line(run_cli, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """A hostile-user review: rigctl devices ended in a ValueError traceback (embedded null byte)."""
    cameras = [dict(c) for c in SIM_RIG["cameras"]]
    cameras[0]["device"] = "/dev/video0\x00x"
    rig = str(write_yaml(tmp_path / "cam.yaml", {**SIM_RIG, "cameras": cameras}))
    one_line(run_cli("devices", rig), EXIT_DEVICE, "camera r0c0: device address '/dev/video0\\x00x': holds a NUL")
    one_line(run_cli("record", rig, "--take", "t", "--frames", "1", "--out", "takes", *DET), EXIT_DEVICE, "NUL")
    tally = {"protocol": "tsl-umd-3.1", "port": "/dev/null\x00x"}
    rig = str(write_yaml(tmp_path / "line.yaml", {**SIM_RIG, "tally": tally}))
    one_line(run_cli("devices", rig), EXIT_DEVICE, "tally line: device address '/dev/null\\x00x': holds a NUL")
    assert not (tmp_path / "takes").exists()
