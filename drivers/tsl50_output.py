"""Tally to TSL UMD 5.0 receivers over UDP (``udp://HOST:PORT``): the whole state in one packet, one display
message per camera. Program lights the left and right tallies and the text red, preview green."""

from __future__ import annotations

import socket

from rigctl.drivers.protocols import tsl50

from rigctl.errors import DeviceError, RigFileError
from rigctl.interfaces import TallyState


def parse_udp(url: str) -> tuple[str, int]:
    if not url.startswith("udp://"):
        raise RigFileError(f"tally port {url!r}: TSL UMD 5.0 goes over UDP, write udp://HOST:PORT")
    host, _, port = url.removeprefix("udp://").rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise RigFileError(f"tally port {url!r}: expected udp://HOST:PORT with a port 1..65535")
    return host.strip("[]"), int(port)


class Tsl50Output:
    def __init__(self, url: str, addresses: dict[str, int], screen: int = 0) -> None:
        self.url = url
        self.addresses = addresses
        self.screen = screen
        host, port = parse_udp(url)
        try:
            info = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        except socket.gaierror as exc:
            raise DeviceError(f"{url}: cannot resolve {host}: {exc}") from None
        self.sock = socket.socket(info[0], socket.SOCK_DGRAM)
        self.target = info[4]

    def packet(self, state: TallyState) -> bytes:
        displays = []
        for name, index in self.addresses.items():
            colour = tsl50.RED if name in state.program else tsl50.GREEN if name in state.preview else tsl50.OFF
            displays.append(tsl50.Display(index, right=colour, text_tally=colour, left=colour, brightness=3, text=name))
        return tsl50.encode(tsl50.Tsl5Packet(self.screen, tuple(displays)))

    def send(self, state: TallyState) -> None:
        try:
            self.sock.sendto(self.packet(state), self.target)
        except OSError as exc:
            raise DeviceError(f"{self.url}: tally not sent: {exc}") from None

    def close(self) -> None:
        self.sock.close()
