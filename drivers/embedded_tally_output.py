"""Tally as Blackmagic embedded tally, inserted into SDI by the SDI bridge: the cameras' own tally lights."""

from __future__ import annotations

from rigctl.drivers.protocols import bmd_tally
from rigctl.drivers.sdi_bridge import SdiBridge

from rigctl.interfaces import TallyState


class EmbeddedTallyOutput:
    def __init__(self, bridge: SdiBridge, camera_ids: dict[str, int]) -> None:
        self.bridge = bridge
        self.camera_ids = camera_ids
        self.cameras = max(camera_ids.values())

    def packet(self, state: TallyState) -> bmd_tally.EmbeddedTally:
        program = frozenset(self.camera_ids[n] for n in state.program if n in self.camera_ids)
        preview = frozenset(self.camera_ids[n] for n in state.preview if n in self.camera_ids)
        return bmd_tally.EmbeddedTally(self.cameras, program, preview)

    def send(self, state: TallyState) -> None:
        self.bridge.send_tally(self.packet(state))

    def settle(self) -> None:
        """Nothing to wait for: the bridge reports its own failures when sent to."""

    def close(self) -> None:
        self.bridge.close()
