"""Shared fixtures. Tests read real data from ../shared (never copied into the project)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import settings

REPO = Path(__file__).resolve().parents[1]


def _shared() -> Path:
    """Where the workplace's shared data live: ``$RIGCTL_SHARED``, else ``shared/`` beside this checkout,
    else beside the checkout this one was cloned from (a throw-away clone in a temporary folder). A test
    that needs data fails on a missing folder, naming it; it is never skipped."""
    if os.environ.get("RIGCTL_SHARED"):
        return Path(os.environ["RIGCTL_SHARED"])
    beside = REPO.parent / "shared"
    if beside.is_dir():
        return beside
    try:
        origin = subprocess.run(
            ["git", "-C", str(REPO), "config", "--get", "remote.origin.url"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        origin = ""
    if origin and Path(origin).is_dir():
        return Path(origin).resolve().parent / "shared"
    return beside


SHARED = _shared()

# A suite started as a background job of a script (`.ci/run &`, nohup) inherits SIGINT ignored, and so would
# every rigctl it starts: the tests that stop a command with Ctrl-C would wait for it forever. The suite takes
# Python's own handler back, and its children then start with the default, as they would from a terminal.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

settings.register_profile("ci", deadline=None, max_examples=200, derandomize=True)
settings.register_profile("dev", deadline=None, max_examples=100)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def rigctl_command() -> list[str]:
    """The installed console script (what a user runs), next to the interpreter running the tests."""
    exe = Path(sys.executable).with_name("rigctl")
    if exe.exists():
        return [str(exe)]
    found = shutil.which("rigctl")
    if found is None:
        raise RuntimeError("the rigctl console script is not installed: pip install -e . first")
    return [found]


@pytest.fixture
def run_cli(tmp_path: Path):
    """Run the real ``rigctl`` console script in a scratch directory; returns CompletedProcess."""

    def run(*argv: str, cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [*rigctl_command(), *argv],
            cwd=cwd or tmp_path,
            capture_output=True,
            text=True,
            timeout=timeout,
            stdin=subprocess.DEVNULL,
        )

    return run


@pytest.fixture(scope="module")
def module_tmp(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[[str], Path]]:
    """``mktemp`` for a module's shared fixtures, whose folders go when the module's last test is done.

    Takes, depth and renders run to gigabytes; kept to the end of the session (as ``tmp_path_factory`` keeps
    them) they filled a CI machine's disk part-way through the suite. Per-test folders go when their test
    passes (``tmp_path_retention_policy = "failed"`` in pyproject.toml)."""
    made: list[Path] = []

    def mktemp(name: str) -> Path:
        made.append(tmp_path_factory.mktemp(name))
        return made[-1]

    yield mktemp
    for path in made:
        shutil.rmtree(path, ignore_errors=True)


def pytest_report_header(config: pytest.Config) -> str:
    """The free space where the tests write, so that a run which fills the disk says so at the top."""
    import tempfile

    where = Path(tempfile.gettempdir())
    return f"free space in {where}: {shutil.disk_usage(where).free / 1e9:.1f} GB"
