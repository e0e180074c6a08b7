"""Host side of the SDI bridge (``docs/sdi-bridge-protocol.md``): camera-control and embedded-tally packets
sent to the bridge over a serial line, each acknowledged, retried on silence or a damaged reply."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from rigctl.drivers.protocols import bmd_control, bmd_tally
from rigctl.drivers.protocols import sdi_bridge as proto
from rigctl.drivers.serial_link import open_link

from rigctl.errors import BridgeNak, DeviceError, ProtocolError

SERIAL = {"baudrate": 115200, "bytesize": 8, "parity": "N", "stopbits": 1}


class SdiBridge:
    """One bridge on one serial line. Thread-safe: one request at a time."""

    def __init__(self, url: str, reply_timeout_s: float = 0.25, tries: int = 3) -> None:
        self.url = url
        self.reply_timeout_s = reply_timeout_s
        self.tries = tries
        self.link = open_link(url, SERIAL, timeout_s=0.05)
        self._decoder = proto.FrameDecoder()
        self._seq = 0
        self._lock = threading.Lock()
        self.retries = 0
        self.on_close: list[Callable[[], None]] = []
        self.hello = self._hello()

    # ---- transport ------------------------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        try:
            self.link.write(data)
            self.link.flush()
        except Exception as exc:  # pyserial raises its own and OS errors
            raise DeviceError(f"{self.url}: bridge line lost: {exc}") from None

    def _read_reply(self, seq: int, deadline: float) -> proto.BridgeFrame | None:
        while time.monotonic() < deadline:
            try:
                data = self.link.read(256)
            except Exception as exc:
                raise DeviceError(f"{self.url}: bridge line lost: {exc}") from None
            for frame in self._decoder.feed(data):
                if frame.sequence == seq and frame.type >= proto.ACK:
                    return frame
                # a late reply to an earlier, retried request: ignore it
        return None

    def request(self, ftype: int, payload: bytes = b"") -> proto.BridgeFrame:
        """Send one frame and return the bridge's reply to it; retried with the same sequence number (the
        bridge applies a repeated number once). Raises DeviceError on silence, BridgeNak on refusal."""
        with self._lock:
            seq = self._seq
            self._seq = (self._seq + 1) % 256
            data = proto.encode(proto.BridgeFrame(ftype, seq, payload))
            garbage = self._decoder.skipped
            for attempt in range(self.tries):
                if attempt:
                    self.retries += 1
                self._write(data)
                reply = self._read_reply(seq, time.monotonic() + self.reply_timeout_s)
                if reply is None:
                    continue
                if reply.type == proto.NAK:
                    if reply.payload[:1] in (bytes([proto.NAK_CHECKSUM]), bytes([proto.NAK_BUSY])):
                        continue  # damaged on the way or queue full: send again
                    raise BridgeNak(
                        f"{self.url}: bridge refused {proto.TYPES[ftype]}: {proto.describe_nak(reply.payload)}"
                    )
                return reply
        garbage = self._decoder.skipped - garbage
        if garbage:  # something answers, but not in the bridge's frames: not silence, say so
            raise DeviceError(
                f"{self.url}: no bridge frame in what the line sent back to {proto.TYPES[ftype]} ({garbage} bytes "
                f"of something else in {self.tries} tries): another device on this port, or another baud rate "
                f"than {SERIAL['baudrate']}?"
            )
        raise DeviceError(
            f"{self.url}: no reply from the SDI bridge to {proto.TYPES[ftype]} within "
            f"{self.reply_timeout_s:.2f} s ({self.tries} tries)"
        )

    def _hello(self) -> proto.Hello:
        try:
            reply = self.request(proto.HELLO)
        except DeviceError:
            self.link.close()
            raise
        if reply.type != proto.HELLO_REPLY:
            self.link.close()
            raise DeviceError(f"{self.url}: bridge answered HELLO with {proto.TYPES[reply.type]}")
        try:
            return proto.decode_hello(reply.payload)
        except ProtocolError as exc:
            self.link.close()
            raise DeviceError(f"{self.url}: {exc}") from None

    # ---- what the bridge does ---------------------------------------------------------------------------
    def send_control(self, messages: list[bmd_control.Message]) -> int:
        """Send camera-control messages, packed into as few packets as the 255-byte limit allows; returns
        the number of packets acknowledged."""
        packets: list[list[bmd_control.Message]] = [[]]
        size = 0
        for msg in messages:
            n = len(bmd_control.encode_message(msg))
            if size + n > bmd_control.MAX_PACKET:
                packets.append([])
                size = 0
            packets[-1].append(msg)
            size += n
        sent = 0
        for packet in packets:
            if packet:
                self.request(proto.CONTROL, bmd_control.encode_packet(packet))
                sent += 1
        return sent

    def send_tally(self, state: bmd_tally.EmbeddedTally) -> None:
        if not self.hello.embedded_tally:
            raise DeviceError(f"{self.url}: this bridge does not insert embedded tally ({self.hello.firmware})")
        self.request(proto.TALLY, bmd_tally.encode(state))

    def query(self, camera_id: int, category: int, parameter: int) -> bmd_control.Message | None:
        """The camera's current value as read back by the bridge, or None when this bridge cannot read back."""
        if not self.hello.readback:
            return None
        reply = self.request(proto.QUERY, proto.encode_query(camera_id, category, parameter))
        if reply.type != proto.STATE:
            raise DeviceError(f"{self.url}: bridge answered QUERY with {proto.TYPES[reply.type]}")
        try:
            msgs = bmd_control.decode_packet(reply.payload)
        except ProtocolError as exc:
            raise DeviceError(f"{self.url}: bridge STATE reply: {exc}") from None
        return msgs[0] if msgs else None

    def close(self) -> None:
        self.link.close()
        for fn in self.on_close:
            fn()
        self.on_close.clear()
