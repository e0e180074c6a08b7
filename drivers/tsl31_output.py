"""Tally to TSL UMD 3.1 receivers over a serial line: one 18-byte frame per camera, the whole state."""

from __future__ import annotations

from rigctl.drivers.protocols import tsl31
from rigctl.drivers.serial_link import open_link

from rigctl.errors import DeviceError
from rigctl.interfaces import TallyState


class Tsl31Output:
    def __init__(self, url: str, addresses: dict[str, int], pad_with_nul: bool = False) -> None:
        self.url = url
        self.addresses = addresses
        self.pad_with_nul = pad_with_nul
        self.link = open_link(url, tsl31.SERIAL)

    def frames(self, state: TallyState) -> bytes:
        out = bytearray()
        for name, address in self.addresses.items():
            tally = (name in state.preview, name in state.program, False, False)
            out += tsl31.encode(tsl31.Tsl31Message(address, tally, 3, name), self.pad_with_nul)
        return bytes(out)

    def send(self, state: TallyState) -> None:
        data = self.frames(state)
        try:
            self.link.write(data)
            self.link.flush()
        except Exception as exc:  # pyserial raises its own and OS errors
            raise DeviceError(f"{self.url}: tally line lost: {exc}") from None

    def settle(self) -> None:
        """Nothing to wait for: a serial line has no receiver to say it dropped the tally."""

    def close(self) -> None:
        self.link.close()
