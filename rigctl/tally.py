"""Tally: which cameras are on program (live) and on preview, sent to whatever outputs the rig has.

The state is the whole truth and is always sent whole (on connect, on change, and periodically by the
shoot UI), so a receiver that missed a frame or was replugged is right again on the next send.
Mapping for TSL UMD: tally 1 = preview, tally 2 = program, full brightness, label = camera name.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable

from rigctl.errors import ParameterError, RigctlError, RigFileError
from rigctl.interfaces import TallyOutput, TallyState
from rigctl.rig import Rig

log = logging.getLogger(__name__)


def tsl_addresses(rig: Rig) -> dict[str, int]:
    """TSL display address per camera: the rig's ``tally.addresses``, default 1..N in row-major order."""
    tally = rig.model.tally
    if tally is None:
        raise RigFileError(f"{rig.source}: rig {rig.name} has no tally section")
    given = tally.addresses or {}
    return {name: given.get(name, i + 1) for i, name in enumerate(rig.camera_names)}


def tally_state(
    rig: Rig, program: list[str], preview: list[str], names: tuple[str, str] = ("--program", "--preview")
) -> TallyState:
    """The state asked for, checked: every camera in ``rig``, none named twice in one list. A camera may be on
    program and preview at once (a switcher with the same source on both buses): TSL 3.1 and the embedded
    tally light both lamps; TSL 5.0 and the shoot UI show program, which wins. Refused with
    :class:`ParameterError` naming the camera and the list by ``names`` (the options of ``rigctl tally``, or the
    shoot UI's words)."""
    known = set(rig.camera_names)
    for cam in [*program, *preview]:
        if cam not in known:
            raise ParameterError(f"camera {cam!r} is not in rig {rig.name} (it has {', '.join(rig.camera_names)})")
    for option, cams in zip(names, (program, preview), strict=True):
        twice = next((cam for i, cam in enumerate(cams) if cam in cams[:i]), None)
        if twice is not None:
            raise ParameterError(f"{option}: camera {twice} is named twice")
    return TallyState(frozenset(program), frozenset(preview))


class TallyService:
    """Keeps a tally output right: sends the whole state on connect, on every change and every second,
    and reopens a lost line with backoff (1, 2, 4 s, capped at 10 s), restoring the state without anyone
    doing anything. A port whose device node comes back is retried at once.

    It never dies silently: every failure, of the line or of a bug, is in :attr:`last_error` (and logged);
    a failure to open is retried with backoff, and anything else stops the service with :attr:`stopped_by`
    saying why."""

    BACKOFF_S = (1.0, 2.0, 4.0, 10.0)

    def __init__(
        self, open_output: Callable[[], TallyOutput], port_path: str | None = None, resend_s: float = 1.0
    ) -> None:
        self._open = open_output
        self._port = port_path
        self._resend_s = resend_s
        self._state = TallyState()
        self._changed = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="tally", daemon=True)
        self.connected = False
        self.last_error = ""
        self.stopped_by = ""  # set when the service stopped on an unexpected error
        self.sends = 0

    def start(self) -> TallyService:
        self._thread.start()
        return self

    def set(self, state: TallyState) -> None:
        self._state = state
        self._changed.set()

    def stop(self) -> None:
        self._stop.set()
        self._changed.set()
        self._thread.join(timeout=5)

    def _node(self) -> tuple[int, int] | None:
        if not self._port or "://" in self._port:
            return None
        try:
            st = os.stat(self._port)
        except OSError:
            return None
        return st.st_ino, st.st_rdev

    def _wait_backoff(self, seconds: float, gone: tuple[int, int] | None) -> None:
        deadline = time.monotonic() + seconds
        while not self._stop.is_set() and time.monotonic() < deadline:
            node = self._node()
            if node is not None and node != gone:
                return  # the device came back (replugged): try now
            time.sleep(0.05)

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        try:
            self._serve()
        except Exception as exc:  # a bug must not kill the tally silently: stop, visibly
            self.connected = False
            self.last_error = self.stopped_by = f"tally service stopped: {type(exc).__name__}: {exc}"
            log.error("%s", self.last_error, exc_info=True)

    def _serve(self) -> None:
        attempt = 0
        output: TallyOutput | None = None
        gone: tuple[int, int] | None = None
        while not self._stop.is_set():
            if output is None:
                try:
                    output = self._open()
                    output.send(self._state)
                    self.sends += 1
                    self.connected, attempt, gone = True, 0, None
                except RigctlError as exc:
                    if output is not None:
                        output.close()
                        output = None
                    if str(exc) != self.last_error:
                        log.warning("tally: %s; retrying", exc)
                    self.connected, self.last_error = False, str(exc)
                    wait = self.BACKOFF_S[min(attempt, len(self.BACKOFF_S) - 1)]
                    attempt += 1
                    self._wait_backoff(wait, gone)
                continue
            self._changed.wait(self._resend_s)
            self._changed.clear()
            if self._stop.is_set():
                break
            try:
                output.send(self._state)
                self.sends += 1
            except RigctlError as exc:
                log.warning("tally: %s; reopening", exc)
                gone = self._node()
                output.close()
                output = None
                self.connected, self.last_error = False, str(exc)
                self._wait_backoff(self.BACKOFF_S[0], gone)
                attempt = 1
        if output is not None:
            output.close()
