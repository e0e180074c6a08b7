"""The reference tools the interop tests compare against: MPEG's RVS and the IV-PSNR authors' software, built
from their public source by the workplace's scripts (``shared/tools/build-rvs``, ``build-ivpsnr``). A script
reuses a binary it built before (in ``$RIGCTL_TOOLS_CACHE``, else its own default cache), so only the first
run on a machine compiles. A tool that cannot be built fails the test, naming the script and its output:
never skipped."""

from __future__ import annotations

import functools
import os
import subprocess
from pathlib import Path

from conftest import SHARED


@functools.cache
def reference_tool(name: str) -> Path:
    """Path of the built ``RVS`` (``name`` "rvs") or ``IVPSNR`` (``name`` "ivpsnr") binary."""
    script = SHARED / "tools" / f"build-{name}"
    if not script.is_file():
        raise RuntimeError(f"{script} is missing: the reference tool {name} cannot be built (see $RIGCTL_SHARED)")
    cache = os.environ.get("RIGCTL_TOOLS_CACHE")
    argv = [str(script)] + ([str(Path(cache) / f"{name}-build")] if cache else [])
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=3600)
    path = Path(proc.stdout.strip().splitlines()[-1]) if proc.stdout.strip() else None
    if proc.returncode != 0 or path is None or not path.is_file():
        raise RuntimeError(f"{script} failed (exit {proc.returncode}): {proc.stderr[-2000:]}")
    return path
