"""``rigctl.allocator.limit_arenas``: a process that estimates depth keeps one allocator arena however many of
its threads allocate, counted by glibc itself (``malloc_stats``) in a fresh process; without it, the same
threads make several."""

from __future__ import annotations

import subprocess
import sys

PROBE = """
import ctypes, sys, threading
import numpy as np
from rigctl.allocator import limit_arenas
if sys.argv[1] == "limit":
    assert limit_arenas()
def work():
    for _ in range(50):
        blocks = [np.ones(30000) for _ in range(20)]  # 240 KB each: below the mmap threshold, from an arena
        del blocks
threads = [threading.Thread(target=work) for _ in range(8)]
for t in threads:
    t.start()
for t in threads:
    t.join()
ctypes.CDLL(None).malloc_stats()  # glibc's own account, on stderr: one "Arena N:" block per arena
"""


def arenas(mode: str) -> int:
    proc = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return sum(line.startswith("Arena ") for line in proc.stderr.splitlines())


def test_depth_processes_keep_one_arena_however_many_threads_allocate() -> None:
    assert arenas("limit") == 1
    assert arenas("default") > 1  # the same threads without the limit: the probe can tell
