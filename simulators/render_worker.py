"""Scene states rendered in a separate process, for the background.

Rendering the motion's later poses in this process while the cameras stream and the recorder writes takes
the interpreter's lock from their threads in many short turns; on a busy two-core machine the capture
threads then fall behind and whole takes are lost. A child process has no share in that lock: the kernel
schedules its render threads against the capture threads fairly, and threads that wake for a frame get
the CPU promptly. (Not at a low priority: beside CPU-bound neighbours it would then starve and miss the
motion's schedule.) It renders with the same code from the same rig and settings, so its bytes are the
same as a render in this process (tests/integration/test_sim_start.py).
"""

from __future__ import annotations

import atexit
import logging
import multiprocessing
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from rigctl.simulators.states import Frames

log = logging.getLogger(__name__)

PREFIX = "rigctl-sim-render-"  # then the owning process's id: a folder whose process is gone is removed


def _sweep_stale_folders() -> None:
    """Remove the temporary folders of processes that died without closing their worker (a signal)."""
    for folder in Path(tempfile.gettempdir()).glob(f"{PREFIX}*"):
        pid = folder.name.removeprefix(PREFIX).split("-", 1)[0]
        if not pid.isdigit() or folder.is_symlink() or not folder.is_dir() or folder.stat().st_uid != os.getuid():
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            shutil.rmtree(folder, ignore_errors=True)
        except PermissionError:
            pass


_array: Any = None  # the child's own simulated array


def _start(build: Callable[[str, str], Any], rig: str, settings: str) -> None:
    """The child's initializer: ``build`` (a module-level function, pickled by name) makes its own array."""
    global _array
    _array = build(rig, settings)


def _render(state: int, folder: str) -> str:
    frames = _array._render_state(state)
    path = Path(folder) / f"state-{state}.npz"
    tmp = Path(folder) / f".state-{state}.npz"
    np.savez(tmp, **dict(zip(_array.names, frames, strict=True)))
    os.replace(tmp, path)
    return str(path)


class RenderWorker:
    """One child process that renders states on request; its files pass through a private folder."""

    def __init__(
        self,
        build: Callable[[str, str], Any],
        rig: str,
        settings: str,
        names: list[str],
        eager: bool = True,
    ) -> None:
        """``build(rig, settings)`` makes the child's array from their JSON (a module-level function: the
        child imports it by name, so this module needs no import of the array's). ``eager``: start the
        process now (its start-up overlaps the first state's render here); else on the first state the disk
        cache did not have."""
        self.names = names
        self._args = (build, rig, settings)
        self.folder: Path | None = None
        self._pool: Any = None
        if eager:
            self._begin()

    def _begin(self) -> None:
        _sweep_stale_folders()
        self.folder = Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-"))
        context = multiprocessing.get_context("spawn")  # never fork a process with running threads
        self._pool = context.Pool(1, initializer=_start, initargs=self._args)
        atexit.register(self.close)  # a short take ends before the last state: no process or files left

    def __call__(self, state: int) -> Frames:
        if self._pool is None:
            self._begin()
        path = Path(self._pool.apply(_render, (state, str(self.folder))))
        with np.load(path) as data:
            out = [data[n] for n in self.names]
        path.unlink(missing_ok=True)
        return out

    def close(self) -> None:
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.terminate()
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)
