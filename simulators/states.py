"""Rendered scene states of a simulated array: kept in memory and on disk across runs, rendered on demand
or by one background thread in the order the stream needs them.

A state is rendered once: whoever asks for it first (a camera delivering a frame, or the background
thread working down its list) renders it, and everyone else asking meanwhile waits for that render.
What a state looks like never depends on who rendered it or when, so the same seed gives the same bytes
however the rendering was timed.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import threading
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

log = logging.getLogger(__name__)

Frames = list[NDArray[np.uint8]]
T = TypeVar("T")


class RenderStopped(RuntimeError):
    """A render asked for after the simulated array was closed."""


class DiskCache:
    """One folder of ``state-N.npz`` files (one array per camera), written atomically."""

    def __init__(self, folder: Path, names: list[str], nbytes: int) -> None:
        self.folder = folder
        self.names = names
        self.nbytes = nbytes

    @classmethod
    def for_inputs(cls, inputs: object, sources: list[Path], names: list[str], nbytes: int) -> DiskCache | None:
        """The folder for these inputs (JSON-able) and simulator source files: same inputs, same bytes.
        ``RIGCTL_SIM_CACHE`` names the root (default ``$XDG_CACHE_HOME/rigctl-sim``); ``off`` disables it."""
        root = os.environ.get("RIGCTL_SIM_CACHE", "")
        if root == "off":
            return None
        base = Path(root) if root else Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "rigctl-sim"
        h = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode())
        for source in sources:
            h.update(source.read_bytes())
        return cls(base / h.hexdigest()[:24], names, nbytes)

    def has(self, state: int) -> bool:
        return (self.folder / f"state-{state}.npz").is_file()

    def load(self, state: int) -> Frames | None:
        try:
            with np.load(self.folder / f"state-{state}.npz") as data:
                out = [data[n] for n in self.names]
        except (OSError, KeyError, ValueError):
            return None
        return out if all(a.nbytes == self.nbytes for a in out) else None

    def keep(self, state: int, frames: Frames) -> None:
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            tmp = self.folder / f".state-{state}-{os.getpid()}-{threading.get_ident()}.npz"
            arrays: dict[str, Any] = dict(zip(self.names, frames, strict=True))  # keywords numpy's stubs mistype
            np.savez(tmp, **arrays)
            os.replace(tmp, self.folder / f"state-{state}.npz")
        except OSError as exc:  # a cache that cannot be written only costs the next run its time
            log.debug("render cache not written: %s", exc)


class StateStore:
    """Every state's frames, each rendered (or loaded from ``disk``) exactly once by ``render``."""

    def __init__(self, render: Callable[[int], Frames], disk: DiskCache | None = None) -> None:
        self._render = render
        self.disk = disk
        self._lock = threading.Lock()
        self._frames: dict[int, Frames] = {}
        self._busy: dict[int, threading.Event] = {}  # state -> set when its render ends (either way)
        self._thread: threading.Thread | None = None
        self._cancel = threading.Event()
        self.rendered: list[int] = []  # states rendered here (not loaded), in order: what the cache saved
        self.error: BaseException | None = None  # what stopped the background thread, if anything

    def ready(self, state: int) -> bool:
        with self._lock:
            return state in self._frames

    def get(self, state: int, render: Callable[[int], Frames] | None = None) -> Frames:
        """The state's frames: at once when ready, after the render under way, or rendered here (by
        ``render`` if given: any renderer gives the same bytes)."""
        while True:
            with self._lock:
                done = self._frames.get(state)
                if done is not None:
                    return done
                pending = self._busy.get(state)
                if pending is None:
                    pending = self._busy[state] = threading.Event()
                    mine = True
                else:
                    mine = False
            if not mine:
                pending.wait()
                continue  # ready now, or the render failed and this caller tries itself
            try:
                out = self._produce(state, render or self._render)
                with self._lock:
                    self._frames[state] = out
            finally:
                with self._lock:
                    del self._busy[state]
                pending.set()
            return out

    def wait(self, state: int, timeout_s: float) -> bool:
        """True once the state is ready: waits up to ``timeout_s`` for a render under way; with none under
        way, renders it here (which may take longer)."""
        with self._lock:
            if state in self._frames:
                return True
            pending = self._busy.get(state)
        if pending is None:
            self.get(state)
            return True
        pending.wait(max(timeout_s, 0.0))
        return self.ready(state)

    def _produce(self, state: int, render: Callable[[int], Frames]) -> Frames:
        out = self.disk.load(state) if self.disk is not None else None
        if out is None:
            out = render(state)
            self.rendered.append(state)
            if self.disk is not None:
                self.disk.keep(state, out)
        return out

    def start(
        self,
        order: Iterable[int],
        first: Callable[[], object] | None = None,
        render: Callable[[int], Frames] | None = None,
        done: Callable[[], object] | None = None,
    ) -> None:
        """Render ``order`` from one background thread (``first`` runs before it: set-up the frames need),
        with ``render`` if given (another process, say), and call ``done`` at the end."""
        if self._thread is not None:
            return
        states = list(order)

        def work() -> None:
            try:
                if first is not None:
                    first()
                for state in states:
                    if self._cancel.is_set():
                        return
                    self.get(state, render)
            except BaseException as exc:  # a camera asking for the state renders it again and raises it
                self.error = exc
                log.debug("background rendering stopped: %s", exc)
            finally:
                if done is not None:
                    done()

        self._thread = threading.Thread(target=work, name="sim-render", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the background thread after the state it is rendering (it is not waited for)."""
        self._cancel.set()

    def unless_stopped(self, work: Callable[..., T], *args: Any) -> T:
        """``work(*args)``, or :class:`RenderStopped` once :meth:`stop` was called: a state's render queues
        every camera's work, and a process that exits waits for its pool's queue (concurrent.futures), so
        work not begun is dropped (nine 8K cameras' renders were minutes and 10 GB after the command ended)."""
        if self._cancel.is_set():
            raise RenderStopped("the simulated array was closed")
        return work(*args)

    def join(self, timeout_s: float | None = None) -> None:
        if self._thread is not None:
            self._thread.join(timeout_s)
