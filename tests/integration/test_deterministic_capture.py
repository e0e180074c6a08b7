"""Deterministic simulated capture (``--sim deterministic=true``): a take recorded on a machine kept busy by two
CPU-bound processes has every frame set, and the same essence and index bytes as the same take recorded
without them. Only the wall-clock fields of the manifest differ."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

FRAMES = 30
# the presenter moving on a quick schedule (a new pose every 5 frames, rendered by the background process
# while the cameras stream), so frames also wait for renders that a busy machine makes slow
SETTINGS = ["deterministic=true", "seed=4", "motion_states=3", "motion_ramp_s=0.2", "skew_us.r2c2=3000"]
WALL_CLOCK = {"take", "started_utc"}  # the take's name, and when it was recorded
WALL_CLOCK_TIMING = {"start_timecode"}  # the time-of-day timecode, from started_utc


def small_rig(folder: Path) -> Path:
    """The simulated 3x3 rig at 320x180, so the renders are quick."""
    from rigctl.rig import load_rig

    data = load_rig("sim-3x3").to_dict()
    data["format"].update(width_px=320, height_px=180)
    path = folder / "small.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def record(out: Path, name: str) -> dict:  # type: ignore[type-arg]
    from tests_support import run_rigctl  # type: ignore[import-not-found]

    sim = [arg for s in SETTINGS for arg in ("--sim", s)]
    rig = str(small_rig(out))
    res = run_rigctl("record", rig, "--take", name, "--frames", str(FRAMES), "--out", str(out), *sim, "--json")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)  # type: ignore[no-any-return]


def without_wall_clock(folder: Path) -> dict:  # type: ignore[type-arg]
    manifest = yaml.safe_load((folder / "take.yaml").read_text())
    for key in WALL_CLOCK:
        manifest.pop(key)
    for key in WALL_CLOCK_TIMING:
        manifest["timing"].pop(key)
    return manifest  # type: ignore[no-any-return]


@pytest.mark.slow
def test_same_bytes_and_every_frame_set_beside_two_cpu_bound_processes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a cache of its own: the loaded take renders every state (slowly, beside the busy processes), the quiet
    # one reads them back from the disk cache
    monkeypatch.setenv("RIGCTL_SIM_CACHE", str(tmp_path / "cache"))
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        loaded = record(tmp_path, "loaded")
    finally:
        for p in busy:
            p.kill()
            p.wait()
    quiet = record(tmp_path, "quiet")

    for summary in (loaded, quiet):
        assert summary["status"] == "complete"
        assert summary["frame_sets"] == FRAMES and summary["complete_sets"] == FRAMES
        for name, cam in summary["cameras"].items():
            assert cam["frames"] == FRAMES, name
            assert cam["source_drops"] == cam["writer_drops"] == cam["not_written"] == 0, name

    a, b = tmp_path / "loaded", tmp_path / "quiet"
    files = sorted(p.relative_to(a) for p in (a / "cameras").iterdir())
    assert len(files) == 18  # nine cameras, an essence and an index each
    for rel in files:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), f"{rel} differs"
    assert (a / "truth").exists()
    for truth in sorted(p.relative_to(a) for p in (a / "truth").rglob("*") if p.is_file()):
        assert (a / truth).read_bytes() == (b / truth).read_bytes(), f"{truth} differs"

    manifest = without_wall_clock(a)
    assert manifest == without_wall_clock(b)
    assert manifest["timing"]["clock"] == "simulated"
    assert manifest["devices"]["settings"]["deterministic"] is True
