"""A careless or hostile user at ``rigctl record`` and at device addresses: each case is refused in one line with
the documented exit status, before anything is allocated or opened, and leaves nothing behind."""

from __future__ import annotations

from pathlib import Path

import pytest
from hostile_support import SIM_RIG, one_line, write_yaml  # type: ignore[import-not-found]

from rigctl.errors import EXIT_DEVICE, EXIT_USAGE

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
