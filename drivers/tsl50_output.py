"""Tally to TSL UMD 5.0 receivers over UDP (``udp://HOST:PORT``) or TCP (``tcp://HOST:PORT``, each packet framed
with DLE/STX: ``protocols.tsl50.frame``): the whole state in one packet, one display message per camera.
Program lights the left and right tallies and the text red, preview green. Over TCP the connection is made
when the output opens and a refused, reset or closed connection is a DeviceError, so the tally service
(``rigctl.tally.TallyService``) connects again with backoff and resends the whole state."""

from __future__ import annotations

import re
import select
import socket
import time

from rigctl.drivers.protocols import tsl50

from rigctl.errors import DeviceError, RigFileError
from rigctl.interfaces import TallyState

SCHEMES = ("udp", "tcp")
CONNECT_TIMEOUT_S = 2.0  # a receiver that does not answer: the service retries with its backoff
SEND_TIMEOUT_S = 2.0  # a receiver that stops reading: its buffer fills, the send fails rather than hangs
SETTLE_S = 0.2  # how long a one-shot send waits for a receiver that drops it (closed or reset) to say so


def parse_url(url: str) -> tuple[str, str, int]:
    """(scheme, host, port) of ``udp://HOST:PORT`` or ``tcp://HOST:PORT`` (an IPv6 host in brackets)."""
    scheme, sep, rest = url.partition("://")
    if not sep or scheme not in SCHEMES:
        raise RigFileError(
            f"tally port {url!r}: TSL UMD 5.0 goes over UDP or TCP, write udp://HOST:PORT or tcp://HOST:PORT"
        )
    host, _, port = rest.rpartition(":")
    bracketed = host.startswith("[") and host.endswith("]") and len(host) > 2
    if (
        not host
        or (("[" in host or "]" in host or ":" in host) and not bracketed)  # IPv6 only as [ADDRESS]
        or not re.fullmatch(r"[0-9]{1,5}", port)  # ASCII digits (str.isdigit takes '²' too)
        or not 0 < int(port) < 65536
    ):
        raise RigFileError(
            f"tally port {url!r}: expected {scheme}://HOST:PORT with a port 1..65535 (an IPv6 host as [ADDRESS])"
        )
    return scheme, host[1:-1] if bracketed else host, int(port)


class Tsl50Output:
    def __init__(self, url: str, addresses: dict[str, int], screen: int = 0) -> None:
        self.url = url
        self.addresses = addresses
        self.screen = screen
        scheme, host, port = parse_url(url)
        self.tcp = scheme == "tcp"
        kind = socket.SOCK_STREAM if self.tcp else socket.SOCK_DGRAM
        try:
            info = socket.getaddrinfo(host, port, type=kind)[0]
        except socket.gaierror as exc:
            raise DeviceError(f"{url}: cannot resolve {host}: {exc}") from None
        except UnicodeError:  # the resolver's IDNA encoding refuses it (a..b, an empty label, a label of 64+)
            raise DeviceError(f"{url}: {host!r:.80} is not a host name") from None
        self.target = info[4]
        self.sock: socket.socket | None = socket.socket(info[0], kind)
        if self.tcp:
            try:
                self.sock.settimeout(CONNECT_TIMEOUT_S)
                self.sock.connect(self.target)
                self.sock.settimeout(SEND_TIMEOUT_S)
                self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # a lamp change goes now
            except OSError as exc:
                self.close()
                raise DeviceError(f"{url}: cannot connect to the tally receiver: {exc.strerror or exc}") from None

    def packet(self, state: TallyState) -> bytes:
        displays = []
        for name, index in self.addresses.items():
            colour = tsl50.RED if name in state.program else tsl50.GREEN if name in state.preview else tsl50.OFF
            displays.append(tsl50.Display(index, right=colour, text_tally=colour, left=colour, brightness=3, text=name))
        return tsl50.encode(tsl50.Tsl5Packet(self.screen, tuple(displays)))

    def send(self, state: TallyState) -> None:
        if self.sock is None:
            raise DeviceError(f"{self.url}: tally not sent: the output is closed")
        if self.tcp and (gone := self._gone(0.0)):  # a closed connection takes one send without a word
            raise DeviceError(f"{self.url}: tally not sent: the receiver {gone} the connection")
        try:
            if self.tcp:
                self.sock.sendall(tsl50.frame(self.packet(state)))
            else:
                self.sock.sendto(self.packet(state), self.target)
        except OSError as exc:
            raise DeviceError(f"{self.url}: tally not sent: {exc.strerror or exc}") from None

    def settle(self, wait: float = SETTLE_S) -> None:
        """After a one-shot send: a DeviceError when the TCP receiver drops the connection within ``wait``
        seconds (a receiver that closes at once, or resets what it did not read: the tally was not shown);
        nothing to wait for over UDP."""
        if self.tcp and self.sock is not None and (gone := self._gone(wait)):
            why = "did not read it" if gone == "reset" else "it may not have been shown"
            raise DeviceError(f"{self.url}: the receiver {gone} the connection at once: {why}")

    def _gone(self, wait: float) -> str | None:
        """``closed`` or ``reset`` when the receiver's end of the connection is gone (seen within ``wait``
        seconds), None while it is open. A TSL 5.0 receiver sends nothing back; whatever it does send is
        read and dropped."""
        assert self.sock is not None
        deadline = time.monotonic() + wait
        while True:
            poll = select.poll()  # not select(): it refuses a descriptor past 1023
            poll.register(self.sock, select.POLLIN)
            if not poll.poll(max(0.0, deadline - time.monotonic()) * 1000):
                return None
            try:
                data = self.sock.recv(4096, socket.MSG_DONTWAIT)
            except (BlockingIOError, TimeoutError):  # nothing after all: look again while there is time
                continue
            except OSError:  # ECONNRESET, or any error the connection now holds
                return "reset"
            if not data:
                return "closed"

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None
