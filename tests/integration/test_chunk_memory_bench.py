"""``benchmarks/chunk_memory.py`` runs (at a small size, two frame sets) and prints each frame set's peaks in
the form the README's table quotes: a smoke test that keeps the benchmark from rotting, not a measurement."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_the_chunk_benchmark_prints_each_frame_sets_peaks() -> None:
    proc = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "chunk_memory.py"), "--size", "320x180", "--frames", "2", "--trim"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert proc.returncode == 0, proc.stderr
    row = r"frame set (\d): held at start ([\d.]+) GiB; depth peak ([\d.]+) GiB .*"
    rows = re.findall(row + r"write peak ([\d.]+) GiB .*held after ([\d.]+)", proc.stdout)
    assert [r[0] for r in rows] == ["0", "1"], proc.stdout
    for _, start, depth, write, after in rows:
        assert 0 < float(start) <= float(depth) and float(write) > 0 and 0 < float(after) < 64
    assert "trim on" in proc.stdout
