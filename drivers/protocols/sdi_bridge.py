"""rigctl SDI bridge protocol, version 1: the serial framing between the host and a bridge that inserts
Blackmagic camera-control and embedded-tally packets into the SDI feed the cameras receive (for example a
microcontroller carrying the Blackmagic 3G-SDI Arduino Shield). The full description for firmware
authors is ``docs/sdi-bridge-protocol.md``; this module is its reference implementation.

Frame (all multi-byte fields little-endian)::

    offset  size  field
    0       2     sync 0xB5 0x62
    2       1     protocol version (1)
    3       1     type
    4       1     sequence number (host counts 0..255 and wraps; a reply carries the request's number)
    5       1     payload length N (0..255)
    6       N     payload
    6+N     2     CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) of bytes 2 .. 5+N

Host -> bridge: HELLO, CONTROL (payload: one camera-control packet as in ``bmd_control``), TALLY (payload:
one embedded-tally packet), QUERY (payload: camera id, category, parameter).
Bridge -> host: ACK (empty payload), NAK (payload: error code, then the offending payload byte offset),
HELLO_REPLY (payload: highest version, capability bits, firmware text), STATE (payload: one camera-control
message carrying the camera's current value, as read back from the camera's SDI output).
"""

from __future__ import annotations

import binascii
import struct
from collections import deque
from dataclasses import dataclass

from rigctl.errors import ProtocolError

SYNC = b"\xb5\x62"
VERSION = 1
HEADER = 6
OVERHEAD = HEADER + 2
MAX_PAYLOAD = 255

# types, host -> bridge
HELLO, CONTROL, TALLY, QUERY = 0x01, 0x02, 0x03, 0x04
# types, bridge -> host
ACK, NAK, HELLO_REPLY, STATE = 0x80, 0x81, 0x82, 0x83
TYPES = {
    HELLO: "HELLO",
    CONTROL: "CONTROL",
    TALLY: "TALLY",
    QUERY: "QUERY",
    ACK: "ACK",
    NAK: "NAK",
    HELLO_REPLY: "HELLO_REPLY",
    STATE: "STATE",
}

# capability bits of HELLO_REPLY
CAP_READBACK = 0x01  # the bridge reads camera-control values back from the cameras' SDI outputs
CAP_EMBEDDED_TALLY = 0x02  # the bridge inserts embedded tally packets

# NAK codes
NAK_CHECKSUM, NAK_VERSION, NAK_TYPE, NAK_PAYLOAD, NAK_UNSUPPORTED, NAK_NO_SDI, NAK_BUSY = 1, 2, 3, 4, 5, 6, 7
NAK_TEXT = {
    NAK_CHECKSUM: "checksum mismatch",
    NAK_VERSION: "protocol version not supported",
    NAK_TYPE: "unknown frame type",
    NAK_PAYLOAD: "payload rejected",
    NAK_UNSUPPORTED: "not supported by this bridge",
    NAK_NO_SDI: "no SDI output (no reference or no signal to insert into)",
    NAK_BUSY: "ancillary queue full, retry",
}


@dataclass(frozen=True)
class BridgeFrame:
    type: int
    sequence: int
    payload: bytes = b""
    version: int = VERSION


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (``binascii.crc_hqx`` with init 0xFFFF); check value of b"123456789" is 0x29B1."""
    return binascii.crc_hqx(data, 0xFFFF)


def encode(frame: BridgeFrame) -> bytes:
    if frame.type not in TYPES:
        raise ProtocolError(f"bridge frame type 0x{frame.type:02x} unknown")
    if not 0 <= frame.sequence <= 255:
        raise ProtocolError(f"bridge sequence number must be 0..255, got {frame.sequence}")
    if len(frame.payload) > MAX_PAYLOAD:
        raise ProtocolError(f"bridge payload of {len(frame.payload)} bytes exceeds {MAX_PAYLOAD}")
    body = bytes([frame.version, frame.type, frame.sequence, len(frame.payload)]) + frame.payload
    return SYNC + body + struct.pack("<H", crc16(body))


def decode(data: bytes) -> BridgeFrame:
    """Exactly one frame; raises ProtocolError naming the byte offset of the first problem."""
    if len(data) < OVERHEAD:
        raise ProtocolError(f"bridge frame of {len(data)} bytes is shorter than {OVERHEAD}")
    if data[:2] != SYNC:
        raise ProtocolError("byte 0: bridge frame does not start with sync B5 62")
    version, ftype, seq, n = data[2:6]
    if len(data) != OVERHEAD + n:
        raise ProtocolError(f"byte 5: payload length {n} does not match the frame ({len(data) - OVERHEAD} bytes)")
    (crc,) = struct.unpack_from("<H", data, HEADER + n)
    if crc != crc16(data[2 : HEADER + n]):
        raise ProtocolError(f"byte {HEADER + n}: checksum mismatch")
    if version != VERSION:
        raise ProtocolError(f"byte 2: bridge protocol version {version} unknown (this speaks {VERSION})")
    if ftype not in TYPES:
        raise ProtocolError(f"byte 3: bridge frame type 0x{ftype:02x} unknown")
    return BridgeFrame(ftype, seq, bytes(data[HEADER : HEADER + n]), version)


class FrameDecoder:
    """Frames out of a byte stream: resynchronises on the sync bytes after garbage, a cut frame or a bad
    checksum, and counts what it skipped. Only the last :attr:`KEEP_ERRORS` error strings are kept (a
    stream of garbage would otherwise grow the list forever); :attr:`error_count` counts them all."""

    KEEP_ERRORS = 64

    def __init__(self) -> None:
        self._buf = bytearray()
        self.skipped = 0
        self.errors: deque[str] = deque(maxlen=self.KEEP_ERRORS)
        self.error_count = 0

    def _error(self, text: str) -> None:
        self.errors.append(text)
        self.error_count += 1

    def feed(self, data: bytes) -> list[BridgeFrame]:
        self._buf += data
        out: list[BridgeFrame] = []
        while True:
            start = self._buf.find(SYNC)
            if start < 0:
                keep = 1 if self._buf.endswith(SYNC[:1]) else 0
                self.skipped += len(self._buf) - keep
                del self._buf[: len(self._buf) - keep]
                return out
            if start:
                self.skipped += start
                del self._buf[:start]
            if len(self._buf) < HEADER:
                return out
            total = OVERHEAD + self._buf[5]
            if len(self._buf) < total:
                later = self._complete_frame_after(1)
                if later < 0:
                    return out
                # a damaged length byte would hold back the frames behind it: skip to the complete one
                self._error(f"byte 5: payload length {self._buf[5]} overruns a later valid frame")
                self.skipped += later
                del self._buf[:later]
                continue
            try:
                out.append(decode(bytes(self._buf[:total])))
            except ProtocolError as exc:
                self._error(str(exc))
                self.skipped += 1
                del self._buf[:1]  # a false sync or a damaged frame: look for the next sync
                continue
            del self._buf[:total]

    def _complete_frame_after(self, start: int) -> int:
        """Offset of the first later sync that starts a complete, valid frame, or -1."""
        pos = self._buf.find(SYNC, start)
        while pos >= 0 and len(self._buf) - pos >= OVERHEAD:
            end = pos + OVERHEAD + self._buf[pos + 5]
            if end <= len(self._buf):
                try:
                    decode(bytes(self._buf[pos:end]))
                    return pos
                except ProtocolError:
                    pass
            pos = self._buf.find(SYNC, pos + 1)
        return -1


@dataclass(frozen=True)
class Hello:
    version: int
    capabilities: int
    firmware: str

    @property
    def readback(self) -> bool:
        return bool(self.capabilities & CAP_READBACK)

    @property
    def embedded_tally(self) -> bool:
        return bool(self.capabilities & CAP_EMBEDDED_TALLY)


def encode_hello(hello: Hello) -> bytes:
    text = hello.firmware.encode("utf-8")[: MAX_PAYLOAD - 2]
    return bytes([hello.version, hello.capabilities]) + text


def decode_hello(payload: bytes) -> Hello:
    if len(payload) < 2:
        raise ProtocolError(f"HELLO_REPLY payload of {len(payload)} bytes is shorter than 2")
    return Hello(payload[0], payload[1], payload[2:].decode("utf-8", errors="replace"))


def encode_query(camera_id: int, category: int, parameter: int) -> bytes:
    for name, v in (("camera id", camera_id), ("category", category), ("parameter", parameter)):
        if not 0 <= v <= 255:
            raise ProtocolError(f"QUERY {name} must be 0..255, got {v}")
    return bytes([camera_id, category, parameter])


def decode_query(payload: bytes) -> tuple[int, int, int]:
    if len(payload) != 3:
        raise ProtocolError(f"QUERY payload must be 3 bytes, got {len(payload)}")
    return payload[0], payload[1], payload[2]


def encode_nak(code: int, offset: int = 0) -> bytes:
    return bytes([code & 0xFF, min(offset, 255)])


def describe_nak(payload: bytes) -> str:
    if not payload:
        return "NAK without a code"
    text = NAK_TEXT.get(payload[0], f"error code {payload[0]}")
    return f"{text} (payload byte {payload[1]})" if payload[0] == NAK_PAYLOAD and len(payload) > 1 else text
