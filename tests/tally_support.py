"""A TSL UMD 5.0 receiver on a real TCP socket, for the contract and integration tests of the TCP tally."""

from __future__ import annotations

import socket
import struct
import threading

from rigctl.drivers.protocols import tsl50

from rigctl.errors import ProtocolError


class TcpReceiver:
    """A TSL 5.0 receiver on a real TCP socket (localhost, ``port`` or any free one): accepts one connection at
    a time, unframes and decodes what arrives in a thread, keeps each display's latest message."""

    def __init__(self, port: int = 0) -> None:
        self.server = socket.create_server(("127.0.0.1", port))
        self.server.settimeout(0.05)
        self.port = self.server.getsockname()[1]
        self.latest: dict[str, tsl50.Display] = {}  # by the display's text
        self.errors: list[str] = []
        self.connections = 0
        self._reset, self._was_reset, self._stop = threading.Event(), threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            self.connections += 1
            conn.settimeout(0.05)
            unframer = tsl50.Unframer()
            with conn:
                while not self._stop.is_set():
                    if self._reset.is_set():  # closed here, by the thread that reads it: the RST goes now
                        conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                        self._reset.clear()
                        self._was_reset.set()
                        break
                    try:
                        data = conn.recv(65536)
                    except TimeoutError:
                        continue
                    except OSError:
                        break
                    if not data:
                        break
                    try:
                        for raw in unframer.feed(data):
                            for d in tsl50.decode(raw).displays:
                                self.latest[d.text] = d
                    except ProtocolError as exc:
                        self.errors.append(str(exc))

    def reset(self) -> None:
        """The receiver drops the connection at once (RST, as a receiver that reboots leaves it)."""
        self._was_reset.clear()
        self._reset.set()
        assert self._was_reset.wait(5), "the receiver never had the connection to reset"

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.server.close()
