"""A careless or hostile user at ``rigctl record`` and at device addresses: each case is refused in one line with
the documented exit status, before anything is allocated or opened, and leaves nothing behind."""

from __future__ import annotations

from pathlib import Path

from hostile_support import one_line  # type: ignore[import-not-found]

from rigctl.errors import EXIT_USAGE

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
