"""Helpers for tests (never imported by runtime code)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def rigctl_exe() -> list[str]:
    exe = Path(sys.executable).with_name("rigctl")
    return [str(exe)]


def make_non_device(path: Path, kind: str) -> Path:
    """Put at ``path`` something that exists but is no device: ``kind`` is "a folder", "a FIFO" or (anything
    else) a regular file. Returns ``path``."""
    if kind == "a folder":
        path.mkdir()
    elif kind == "a FIFO":
        os.mkfifo(path)
    else:
        path.write_text("")
    return path


def run_rigctl(*argv: str, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*rigctl_exe(), *argv], cwd=cwd, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL
    )


def oiio_info(path: Path) -> str:
    """``oiiotool --info -v`` of an image: what OpenImageIO (a reader nobody here wrote) makes of it."""
    proc = subprocess.run(["oiiotool", "--info", "-v", str(path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr  # oiiotool comes from Debian's openimageio-tools (.ci/run)
    return proc.stdout


def rectified_ndc_error(take: Path, camera: str, exr: Path, points: int = 50, seed: int = 2) -> float:
    """The largest distance in pixels between where ``exr``'s ``worldToNDC`` puts random points 1.5-4 m ahead
    of ``camera`` and where ``take``'s rectification record (its common K at the camera's rectified centre,
    rotation identity in the rectified frame) puts them."""
    import numpy as np

    from rigctl.exr import read_exr
    from rigctl.exrcam import project_ndc
    from rigctl.take.manifest import read_manifest

    rect = read_manifest(take).rectification
    assert rect is not None, take
    K, centre = np.array(rect.K), np.array(rect.positions_m[camera])
    size = (rect.image_size[0], rect.image_size[1])
    m = np.asarray(read_exr(exr)[1]["worldToNDC"], np.float64)
    rng = np.random.default_rng(seed)
    err = 0.0
    for _ in range(points):
        p = centre + np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.4, 0.4), rng.uniform(1.5, 4.0)])
        q = K @ (p - centre)
        err = max(err, float(np.abs(np.array(project_ndc(m, p, size)) - q[:2] / q[2]).max()))
    return err
