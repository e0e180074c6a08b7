"""Tally: which cameras are on program (live) and on preview, sent to whatever outputs the rig has.

The state is the whole truth and is always sent whole (on connect, on change, and periodically by the
shoot UI), so a receiver that missed a frame or was replugged is right again on the next send.
Mapping for TSL UMD: tally 1 = preview, tally 2 = program, full brightness, label = camera name.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Protocol

from rigctl.errors import RigFileError
from rigctl.rig import Rig

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TallyState:
    program: frozenset[str] = field(default_factory=frozenset)
    preview: frozenset[str] = field(default_factory=frozenset)

    @classmethod
    def recording(cls, rig: Rig) -> TallyState:
        """A recording take puts every camera on program."""
        return cls(program=frozenset(rig.camera_names))


class TallyOutput(Protocol):
    def send(self, state: TallyState) -> None:
        """Send the complete state."""

    def close(self) -> None: ...


def tsl_addresses(rig: Rig) -> dict[str, int]:
    """TSL display address per camera: the rig's ``tally.addresses``, default 1..N in row-major order."""
    tally = rig.model.tally
    if tally is None:
        raise RigFileError(f"{rig.source}: rig {rig.name} has no tally section")
    given = tally.addresses or {}
    return {name: given.get(name, i + 1) for i, name in enumerate(rig.camera_names)}
