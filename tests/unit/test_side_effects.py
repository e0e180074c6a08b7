"""Process-wide settings are made where they take effect: OpenBLAS reads OPENBLAS_NUM_THREADS once, when numpy
is first imported, so the command line sets it before anything it imports brings numpy in."""

from __future__ import annotations

import os
import subprocess
import sys

PROBE = """
import importlib.abc, os, sys
seen = []
class Probe(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "numpy" and not seen:
            seen.append(os.environ.get("OPENBLAS_NUM_THREADS"))
        return None
sys.meta_path.insert(0, Probe())
import {module}
import numpy
print(repr(seen[0]))
"""


def _env_at_numpy_import(module: str) -> str:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    out = subprocess.run(
        [sys.executable, "-c", PROBE.format(module=module)], env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.strip()


def test_the_cli_sets_openblas_threads_before_numpy_is_imported() -> None:
    assert _env_at_numpy_import("rigctl.cli.main") == "'1'"


def test_the_probe_sees_a_setting_made_too_late() -> None:
    """The check can fail: a module that imports numpy before setting the variable is caught."""
    assert _env_at_numpy_import("rigctl.depth.cost") == "None"
