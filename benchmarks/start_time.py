"""Start-up on the simulated rig: seconds from launch until ``rigctl record`` has created its take folder,
and until ``rigctl tui`` shows its camera grid, on a cold render cache and then a warm one.

Each command is the installed console script, as a user runs it (the record with --force: a shared disk
that reads slow at that moment is preflight's business, not start-up's); the record is stopped with Ctrl-C once
its folder exists, the shoot UI (in a pseudo-terminal) with ``q`` once its grid is drawn. Cold is a
fresh, empty render cache (the first run on a machine, also what ``RIGCTL_SIM_CACHE=off`` gives); warm is
the same cache after the cold runs filled it. The target is 3 s for both.

    python benchmarks/start_time.py [RIG] [--runs N]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import pty
import select
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 3.0
LIMIT_S = 60.0


def rigctl() -> str:
    exe = Path(sys.executable).with_name("rigctl")
    return str(exe) if exe.exists() else (shutil.which("rigctl") or "rigctl")


def record_start(rig: str, work: Path, env: dict[str, str]) -> tuple[float, float]:
    """Seconds until ``rigctl record --seconds 60`` has created its take folder, and until it records (its
    first frames arrived and the take's start instant is set: ``take.yaml`` written)."""
    out = Path(tempfile.mkdtemp(dir=work))
    folder = out / "t"
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [rigctl(), "record", rig, "--take", "t", "--seconds", "60", "--out", str(out), "--force"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        while not folder.exists():
            if proc.poll() is not None:
                raise SystemExit(
                    f"rigctl record ended before creating its take: {proc.stderr.read() if proc.stderr else ''}"
                )
            if time.perf_counter() - t0 > LIMIT_S:
                raise SystemExit(f"rigctl record: no take folder after {LIMIT_S:.0f} s")
            time.sleep(0.01)
        took = time.perf_counter() - t0
        while not (folder / "take.yaml").exists() and proc.poll() is None:  # recording: Ctrl-C now ends it
            time.sleep(0.01)
        recording = time.perf_counter() - t0
        proc.send_signal(signal.SIGINT)  # ends the take at the next frame instant, as Ctrl-C does
        proc.wait(timeout=LIMIT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return took, recording


def tui_start(rig: str, work: Path, env: dict[str, str]) -> tuple[float, float]:
    """Seconds until ``rigctl tui`` has drawn every camera's tile (the last camera's name on screen)."""
    from rigctl.rig import load_rig  # only to know the last camera's name

    last = load_rig(rig).camera_names[-1]
    out = Path(tempfile.mkdtemp(dir=work))
    env = {**env, "TERM": "xterm-256color", "COLUMNS": "160", "LINES": "48"}
    t0 = time.perf_counter()
    pid, fd = pty.fork()
    if pid == 0:  # the child: the shoot UI on the pseudo-terminal
        os.execvpe(rigctl(), [rigctl(), "tui", rig, "--out", str(out)], env)
    seen = b""
    took = None
    try:
        while took is None and time.perf_counter() - t0 < LIMIT_S:
            ready, _, _ = select.select([fd], [], [], 0.05)
            if not ready:
                continue
            try:
                chunk = os.read(fd, 65536)
            except OSError:
                break
            seen = (seen + chunk)[-4096:]
            if last.encode() in seen:
                took = time.perf_counter() - t0
        if took is None:
            raise SystemExit(f"rigctl tui: no camera grid after {LIMIT_S:.0f} s")
        os.write(fd, b"q")
        deadline = time.perf_counter() + 20
        while time.perf_counter() < deadline:
            if os.waitpid(pid, os.WNOHANG)[0]:
                pid = 0
                break
            select.select([fd], [], [], 0.1)
            with contextlib.suppress(OSError):
                os.read(fd, 65536)
    finally:
        if pid:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        os.close(fd)
    return took, took


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rig", nargs="?", default="sim-3x3")
    parser.add_argument("--runs", type=int, default=1, help="runs of each (the median is printed)")
    parser.add_argument("--no-tui", action="store_true", help="measure rigctl record only")
    ns = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="rigctl-start-", dir="/work" if os.path.isdir("/work") else None))
    try:
        rows = []
        kinds = [("record", record_start)] + ([] if ns.no_tui else [("tui", tui_start)])
        for kind, measure in kinds:
            cold, warm = [], []
            for _ in range(ns.runs):
                cache = Path(tempfile.mkdtemp(dir=work))  # a fresh, empty render cache
                env = {**os.environ, "RIGCTL_SIM_CACHE": str(cache)}
                cold.append(measure(ns.rig, work, env))
                warm.append(measure(ns.rig, work, env))
            medians = [[statistics.median(x) for x in zip(*runs, strict=True)] for runs in (cold, warm)]
            rows.append((kind, medians[0], medians[1]))
        load = os.getloadavg()[0]
        print(f"start-up on {ns.rig}, {os.cpu_count()} CPUs, load average {load:.1f}; target {TARGET_S:.0f} s")
        for kind, (cold_s, cold_rec), (warm_s, warm_rec) in rows:
            what = "take folder created" if kind == "record" else "camera grid shown"
            print(
                f"  rigctl {kind:<6} {what}: cold {cold_s:5.2f} s ({cold_s / TARGET_S:.2f}x target), "
                f"warm {warm_s:5.2f} s ({warm_s / TARGET_S:.2f}x target), cold/warm {cold_s / warm_s:.2f}"
            )
            if kind == "record":
                print(f"  rigctl record  recording (first frames in): cold {cold_rec:5.2f} s, warm {warm_rec:5.2f} s")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
