"""Blackmagic SDI camera control protocol (Studio / Micro Studio Camera 4K), as carried in SDI ancillary
data (DID/SDID 0x51/0x53). Little-endian.

    byte 0  destination camera (0..254; 255 = all)     byte 4  category
    byte 1  command length (bytes from byte 4 on)      byte 5  parameter
    byte 2  command id (0 = change configuration)      byte 6  data type
    byte 3  reserved (0)                               byte 7  operation (0 assign, 1 offset/toggle)
    byte 8.. data (an array of the data type), then zero padding to a multiple of 4 bytes.

Up to 64 bytes per message and 255 per blanking packet; several messages may share a packet.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from rigctl.errors import ProtocolError

VOID, INT8, INT16, INT32, INT64, UTF8, FIXED16 = 0, 1, 2, 3, 4, 5, 128
ASSIGN, OFFSET = 0, 1
ALL_CAMERAS = 255
MAX_MESSAGE = 64
MAX_PACKET = 255
_FORMAT = {INT8: "b", INT16: "h", INT32: "i", INT64: "q", FIXED16: "h"}

# parameters a rig needs: (category, parameter) -> (name, data type)
PARAMETERS = {
    (0, 0): ("focus", FIXED16),
    (0, 1): ("instant autofocus", VOID),
    (0, 2): ("aperture f-stop", FIXED16),
    (0, 3): ("aperture normalised", FIXED16),
    (0, 6): ("optical image stabilisation", VOID),
    (1, 0): ("video mode", INT8),
    (1, 1): ("sensor gain", INT8),
    (1, 2): ("white balance", INT16),
    (1, 5): ("exposure", INT32),
    (4, 2): ("zebra level", FIXED16),
    (5, 0): ("tally brightness", FIXED16),
    (5, 1): ("front tally brightness", FIXED16),
    (5, 2): ("rear tally brightness", FIXED16),
    (6, 0): ("reference source", INT8),
    (6, 1): ("reference offset", INT32),
    (7, 0): ("real time clock", INT32),
    (8, 1): ("gamma adjust", FIXED16),
}


@dataclass(frozen=True)
class Message:
    destination: int
    category: int
    parameter: int
    data_type: int = VOID
    operation: int = ASSIGN
    values: tuple[float, ...] | str = ()


def _data(msg: Message) -> bytes:
    if msg.data_type == VOID:
        return bytes(int(v) & 0xFF for v in msg.values) if not isinstance(msg.values, str) else b""
    if msg.data_type == UTF8:
        if not isinstance(msg.values, str):
            raise ProtocolError("UTF-8 parameters take a string")
        return msg.values.encode("utf-8")
    fmt = _FORMAT.get(msg.data_type)
    if fmt is None or isinstance(msg.values, str):
        raise ProtocolError(f"data type {msg.data_type} unknown or not numeric")
    values = [round(v * 2048) if msg.data_type == FIXED16 else int(v) for v in msg.values]
    try:
        return struct.pack("<" + fmt * len(values), *values)
    except struct.error:
        raise ProtocolError(f"value out of range for data type {msg.data_type}: {msg.values}") from None


def encode_message(msg: Message) -> bytes:
    if not 0 <= msg.destination <= 255:
        raise ProtocolError(f"destination must be 0..255, got {msg.destination}")
    data = _data(msg)
    length = 4 + len(data)
    out = bytes([msg.destination, length, 0, 0, msg.category, msg.parameter, msg.data_type, msg.operation]) + data
    out += b"\0" * (-len(out) % 4)
    if len(out) > MAX_MESSAGE:
        raise ProtocolError(f"message of {len(out)} bytes exceeds {MAX_MESSAGE}")
    return out


def encode_packet(messages: list[Message]) -> bytes:
    out = b"".join(encode_message(m) for m in messages)
    if len(out) > MAX_PACKET:
        raise ProtocolError(f"packet of {len(out)} bytes exceeds {MAX_PACKET}: split it")
    return out


def decode_packet(data: bytes) -> list[Message]:
    """Every message of a packet; raises ProtocolError naming the byte offset of the first problem."""
    out = []
    pos = 0
    while pos < len(data):
        if len(data) - pos < 8:
            if not any(data[pos:]):
                break  # trailing padding
            raise ProtocolError(f"byte {pos}: message header cut short")
        dest, length, command, _, category, parameter, dtype, op = data[pos : pos + 8]
        if command != 0:
            raise ProtocolError(f"byte {pos + 2}: command id {command} unknown (0 = change configuration)")
        if length < 4:
            raise ProtocolError(f"byte {pos + 1}: command length {length} is below 4")
        total = 4 + length + (-(4 + length) % 4)
        if pos + 4 + length > len(data) or total > MAX_MESSAGE:
            raise ProtocolError(f"byte {pos + 1}: command length {length} runs past the packet")
        raw = data[pos + 8 : pos + 4 + length]
        values: tuple[float, ...] | str
        if dtype == VOID:
            values = tuple(raw)
        elif dtype == UTF8:
            try:
                values = raw.decode("utf-8")
            except UnicodeDecodeError:
                raise ProtocolError(f"byte {pos + 8}: invalid UTF-8") from None
        elif dtype in _FORMAT:
            size = struct.calcsize(_FORMAT[dtype])
            if len(raw) % size:
                raise ProtocolError(f"byte {pos + 8}: {len(raw)} data bytes are not whole values of type {dtype}")
            ints = struct.unpack("<" + _FORMAT[dtype] * (len(raw) // size), raw)
            values = tuple(v / 2048 for v in ints) if dtype == FIXED16 else tuple(ints)
        else:
            raise ProtocolError(f"byte {pos + 6}: data type {dtype} unknown")
        if op not in (ASSIGN, OFFSET):
            raise ProtocolError(f"byte {pos + 7}: operation {op} unknown")
        out.append(Message(dest, category, parameter, dtype, op, values))
        pos += total
    return out
