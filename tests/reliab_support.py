"""Helpers of the output-safety, fault-injection and mutation tests (never imported by runtime code)."""

from __future__ import annotations

import json
import shlex
import shutil
import struct
import subprocess
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from hostile_support import SIM_RIG, write_yaml  # type: ignore[import-not-found]
from tests_support import rigctl_exe  # type: ignore[import-not-found]

from rigctl.exr import read_exr
from rigctl.pfm import read_pfm
from rigctl.publish import TEMP_SUFFIX
from rigctl.take.index import RECORD, RECORD_SIZE

CAMS = [f"r{r}c{c}" for r in range(3) for c in range(3)]


def rigctl(*argv: str, timeout: float = 120, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*rigctl_exe(), *argv], capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL, cwd=cwd
    )


def make_tiny(root: Path, frames: int = 3, width: int = 96, height: int = 54) -> tuple[Path, Path]:
    """A recorded take of the simulated 3x3 rig (motion off, tiny frames) and its rectified take."""
    rig = dict(SIM_RIG, format={**SIM_RIG["format"], "width_px": width, "height_px": height})
    write_yaml(root / "tiny.yaml", rig)
    res = rigctl(
        "record", str(root / "tiny.yaml"), "--take", "t", "--frames", str(frames), "--out", str(root),
        "--sim", "motion=false", "--sim", "deterministic=true", "--force",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    res = rigctl(
        "rectify", str(root / "t"), "--calibration", str(root / "t/truth/calibration.yaml"), "--out", str(root / "rect")
    )
    assert res.returncode == 0, res.stderr
    return root / "t", root / "rect"


def record_tiny(root: Path, name: str, frames: int = 2, *sim: str) -> Path:
    """A take ``root/name`` of the simulated 3x3 rig at 96x54, deterministic, with ``sim`` settings (KEY=VALUE)."""
    rig = dict(SIM_RIG, format={**SIM_RIG["format"], "width_px": 96, "height_px": 54})
    write_yaml(root / "tiny.yaml", rig)
    settings = [a for kv in ("deterministic=true", *sim) for a in ("--sim", kv)]
    res = rigctl(
        "record", str(root / "tiny.yaml"), "--take", name, "--frames", str(frames), "--out", str(root), "--force",
        *settings,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return root / name


def copy_take(take: Path, dest: Path) -> Path:
    shutil.copytree(take, dest)
    return dest


def edit_manifest(take: Path, edit: Callable[[dict[str, Any]], None]) -> None:
    path = take / "take.yaml"
    data = yaml.safe_load(path.read_text())
    edit(data)
    path.write_text(yaml.safe_dump(data, sort_keys=False))


def camera_file(take: Path, cam: str, kind: str) -> Path:
    data = yaml.safe_load((take / "take.yaml").read_text())
    return take / data["cameras"][cam][kind]


# "res": the camera tag of index version 2 (rigctl.take.index.camera_tag), 0 in version 1
FIELDS = ("magic", "version", "flags", "sequence", "capture_ns", "host_ns", "offset", "size", "crc", "set", "tc", "res")


def rewrite_records(index: Path, edit: Callable[[int, dict[str, Any]], None]) -> None:
    """Rewrite every record of ``index`` through ``edit(i, fields)``, each with a valid record CRC: a lie, not
    damage."""
    data = bytearray(index.read_bytes())
    for i in range(len(data) // RECORD_SIZE):
        at = i * RECORD_SIZE
        fields = dict(zip(FIELDS, RECORD.unpack_from(data, at), strict=True))
        edit(i, fields)
        RECORD.pack_into(data, at, *(fields[k] for k in FIELDS))
        struct.pack_into("<I", data, at + 60, zlib.crc32(bytes(data[at : at + 60])))
    index.write_bytes(bytes(data))


def in_mount(
    mountpoint: Path, options: str, *argv: str, timeout: float = 120
) -> subprocess.CompletedProcess[str] | None:
    """Run ``rigctl argv`` in a private mount namespace where ``mountpoint`` is a fresh tmpfs mounted with
    ``options`` (``ro``, ``size=64k``); None when this machine does not allow it (not root)."""
    if shutil.which("unshare") is None:
        return None
    mountpoint.mkdir(parents=True, exist_ok=True)
    cmd = " ".join(shlex.quote(a) for a in [*rigctl_exe(), *argv])
    script = f"mount -t tmpfs -o {options} tmpfs {shlex.quote(str(mountpoint))} || exit 99; exec {cmd}"
    res = subprocess.run(
        ["unshare", "-m", "--propagation", "private", "sh", "-c", script],
        capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    return None if res.returncode == 99 else res


def published(out: Path) -> dict[str, bytes]:
    """Every file under ``out`` by its relative name, each proven whole by reading it as its format."""
    files = {}
    for p in sorted(out.rglob("*")):
        if not p.is_file() or p.name.endswith(TEMP_SUFFIX):
            continue
        data = p.read_bytes()
        if p.suffix == ".png":
            import cv2
            import numpy as np

            assert cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) is not None, p
        elif p.suffix == ".exr":
            read_exr(p)
        elif p.suffix == ".pfm":
            read_pfm(p)
        elif p.suffix == ".json":
            json.loads(data)
        files[str(p.relative_to(out))] = data
    return files
