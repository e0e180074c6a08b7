"""Helpers of the hostile-input tests (never imported by runtime code)."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import yaml

REPO = Path(__file__).resolve().parents[1]
SIM_RIG = yaml.safe_load((REPO / "rigs" / "sim-3x3.yaml").read_text())


def one_line(res: subprocess.CompletedProcess[str], code: int, *fragments: str) -> str:
    """The run exited with ``code`` and said one line (no traceback) holding every fragment; returns it."""
    assert res.returncode == code, (res.returncode, res.stderr)
    lines = [ln for ln in res.stderr.strip().splitlines() if not ln.startswith("warning:")]
    assert len(lines) == 1, res.stderr
    assert "Traceback" not in res.stderr
    for f in fragments:
        assert f in lines[0], (f, lines[0])
    return lines[0]


def write_yaml(path: Path, data: Any) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def rig_with(tmp_path: Path, **sections: Any) -> Path:
    """The simulated rig without its control sections, plus ``sections``, written to ``tmp_path/rig.yaml``."""
    rig = {k: v for k, v in SIM_RIG.items() if k not in ("tally", "camera_control")}
    rig.update(sections)
    return write_yaml(tmp_path / "rig.yaml", rig)
