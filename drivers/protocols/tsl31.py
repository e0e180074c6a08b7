"""TSL UMD 3.1: fixed 18-byte frames on a one-way RS-422/485 multi-drop line (38400 baud, 8E1).

    byte 0      0x80 + address (0..126)
    byte 1      control: bits 0-3 tally 1-4, bits 4-5 brightness (0..3), bit 6 reserved, bit 7 = 0
    bytes 2-17  16 displayable ASCII characters (space padded; some receivers want NUL padding)

Only the header byte has bit 7 set, which is what lets a receiver find frames again after garbage.
"""

from __future__ import annotations

from dataclasses import dataclass

from rigctl.errors import ProtocolError

FRAME = 18
TEXT = 16
SERIAL = {"baudrate": 38400, "bytesize": 8, "parity": "E", "stopbits": 1}


@dataclass(frozen=True)
class Tsl31Message:
    address: int
    tally: tuple[bool, bool, bool, bool]
    brightness: int = 3
    text: str = ""


def encode(msg: Tsl31Message, pad_with_nul: bool = False) -> bytes:
    if not 0 <= msg.address <= 126:
        raise ProtocolError(f"TSL 3.1 address must be 0..126, got {msg.address}")
    if not 0 <= msg.brightness <= 3:
        raise ProtocolError(f"TSL 3.1 brightness must be 0..3, got {msg.brightness}")
    if any(not 0x20 <= ord(ch) <= 0x7E for ch in msg.text):
        raise ProtocolError(f"TSL 3.1 text must be printable ASCII, got {msg.text!r}")
    control = sum(1 << i for i, on in enumerate(msg.tally) if on) | (msg.brightness << 4)
    text = msg.text[:TEXT].encode("ascii").ljust(TEXT, b"\0" if pad_with_nul else b" ")
    return bytes([0x80 + msg.address, control]) + text


def decode(frame: bytes) -> Tsl31Message:
    """One complete 18-byte frame."""
    if len(frame) != FRAME:
        raise ProtocolError(f"TSL 3.1 frame must be {FRAME} bytes, got {len(frame)}")
    if frame[0] < 0x80 or frame[0] == 0xFF:
        raise ProtocolError(f"byte 0: TSL 3.1 header must be 0x80..0xFE, got 0x{frame[0]:02X}")
    for i in range(1, FRAME):
        if frame[i] & 0x80:
            raise ProtocolError(f"byte {i}: 0x{frame[i]:02X} has bit 7 set (only the header may)")
    control = frame[1]
    tally = (bool(control & 1), bool(control & 2), bool(control & 4), bool(control & 8))
    text = frame[2:].decode("ascii").rstrip(" \0")
    return Tsl31Message(frame[0] - 0x80, tally, (control >> 4) & 3, text)


class Tsl31Decoder:
    """Frames from a byte stream: garbage is skipped (and counted) until the next valid header."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.skipped = 0

    def feed(self, data: bytes) -> list[Tsl31Message]:
        self._buf += data
        out: list[Tsl31Message] = []
        buf = self._buf
        while True:
            start = next((i for i, b in enumerate(buf) if 0x80 <= b <= 0xFE), None)
            if start is None:
                self.skipped += len(buf)
                buf.clear()
                break
            if start:
                self.skipped += start
                del buf[:start]
            if len(buf) < FRAME:
                break
            bad = next((i for i in range(1, FRAME) if buf[i] & 0x80), None)
            if bad is not None:  # a header inside: the frame before it was cut short
                self.skipped += bad
                del buf[:bad]
                continue
            out.append(decode(bytes(buf[:FRAME])))
            del buf[:FRAME]
        return out
