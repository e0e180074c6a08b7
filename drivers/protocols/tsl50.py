"""TSL UMD 5.0 packets (UDP; little-endian).

    PBC u16 (bytes after this field), VER u8, FLAGS u8 (bit0 UTF-16LE text, bit1 screen control),
    SCREEN u16 (0xFFFF broadcast), then per display: INDEX u16 (0xFFFF broadcast), CONTROL u16,
    LENGTH u16, TEXT.  CONTROL: bits 0-1 right tally, 2-3 text tally, 4-5 left tally, 6-7 brightness,
    bit 15 control data. Tally colours: 0 off, 1 red, 2 green, 3 amber.

Over TCP each packet is framed (:func:`frame`, :class:`Unframer`): DLE STX (0xFE 0x02) before it, and every
0xFE inside it sent twice; nothing after it (the byte count says where it ends) and PBC counts the packet
before stuffing. Checked against an independent open implementation (the ``tsl-umd-v5`` package, which
cites TSL's document), not against TSL's document itself nor a hardware receiver.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from rigctl.errors import ProtocolError

OFF, RED, GREEN, AMBER = 0, 1, 2, 3


@dataclass(frozen=True)
class Display:
    index: int
    right: int = OFF
    text_tally: int = OFF
    left: int = OFF
    brightness: int = 3
    text: str = ""


@dataclass(frozen=True)
class Tsl5Packet:
    screen: int = 0
    displays: tuple[Display, ...] = field(default_factory=tuple)
    utf16: bool = False
    version: int = 0


BROADCAST = 0xFFFF  # SCREEN or INDEX: every screen, or every display of the screen


def encode(packet: Tsl5Packet) -> bytes:
    """The packet on the wire. Any 16-bit SCREEN and INDEX is encoded, broadcast included: which of them a
    rig may use is the rig file's business (``rigctl.rig.TALLY_ADDRESS_MAX``)."""
    if not 0 <= packet.screen <= 0xFFFF:
        raise ProtocolError(f"TSL 5.0 screen must be 0..65535, got {packet.screen}")
    body = bytearray()
    for d in packet.displays:
        for name, v, top in (
            ("right", d.right, 3),
            ("text_tally", d.text_tally, 3),
            ("left", d.left, 3),
            ("brightness", d.brightness, 3),
        ):
            if not 0 <= v <= top:
                raise ProtocolError(f"TSL 5.0 {name} must be 0..{top}, got {v}")
        if not 0 <= d.index <= 0xFFFF:
            raise ProtocolError(f"TSL 5.0 display index must be 0..65535, got {d.index}")
        control = d.right | (d.text_tally << 2) | (d.left << 4) | (d.brightness << 6)
        text = d.text.encode("utf-16-le" if packet.utf16 else "ascii", errors="strict")
        body += struct.pack("<HHH", d.index, control, len(text)) + text
    head = struct.pack("<BBH", packet.version, 1 if packet.utf16 else 0, packet.screen)
    pbc = len(head) + len(body)
    if pbc > 0xFFFF:
        raise ProtocolError(f"TSL 5.0 packet too long ({pbc} bytes)")
    return struct.pack("<H", pbc) + head + bytes(body)


def decode(data: bytes) -> Tsl5Packet:
    if len(data) < 6:
        raise ProtocolError(f"TSL 5.0 packet of {len(data)} bytes is shorter than its 6-byte header")
    (pbc,) = struct.unpack_from("<H", data, 0)
    if pbc + 2 != len(data):
        raise ProtocolError(f"byte 0: TSL 5.0 byte count {pbc} does not match the packet ({len(data) - 2} bytes)")
    version, flags, screen = struct.unpack_from("<BBH", data, 2)
    utf16 = bool(flags & 1)
    pos = 6
    displays = []
    while pos < len(data):
        if pos + 6 > len(data):
            raise ProtocolError(f"byte {pos}: display message cut short")
        index, control, length = struct.unpack_from("<HHH", data, pos)
        pos += 6
        if pos + length > len(data):
            raise ProtocolError(f"byte {pos}: text of {length} bytes runs past the packet")
        raw = data[pos : pos + length]
        pos += length
        try:
            text = raw.decode("utf-16-le" if utf16 else "ascii")
        except UnicodeDecodeError:
            raise ProtocolError(f"byte {pos - length}: display text is not valid") from None
        displays.append(Display(index, control & 3, (control >> 2) & 3, (control >> 4) & 3, (control >> 6) & 3, text))
    return Tsl5Packet(screen, tuple(displays), utf16, version)


DLE, STX = 0xFE, 0x02  # TCP framing: DLE STX starts a packet; a DLE inside it is sent as DLE DLE


def frame(packet: bytes) -> bytes:
    """A packet (``encode``'s bytes) as sent over TCP."""
    return bytes((DLE, STX)) + packet.replace(bytes((DLE,)), bytes((DLE, DLE)))


class Unframer:
    """Packets out of a TCP byte stream (what a receiver does with :func:`frame`'s bytes), fed in any pieces.
    Bytes between packets and a DLE inside one followed by anything but DLE are a ProtocolError naming the
    stream's byte offset."""

    def __init__(self) -> None:
        self.offset = 0  # bytes of the stream fed so far
        self._packet: bytearray | None = None  # unstuffed bytes of the packet being read, None between packets
        self._dle = False  # the last byte was a DLE (its meaning waits for the next one)

    def feed(self, data: bytes) -> list[bytes]:
        out: list[bytes] = []
        for b in data:
            at = self.offset
            self.offset += 1
            if self._packet is None:
                if not self._dle:
                    if b != DLE:
                        raise ProtocolError(f"byte {at}: 0x{b:02X} between packets (a packet starts DLE STX)")
                    self._dle = True
                    continue
                self._dle = False
                if b != STX:
                    raise ProtocolError(f"byte {at}: DLE followed by 0x{b:02X}, not STX, between packets")
                self._packet = bytearray()
                continue
            if self._dle:
                self._dle = False
                if b != DLE:
                    raise ProtocolError(f"byte {at}: DLE followed by 0x{b:02X} inside a packet (DLE is sent twice)")
            elif b == DLE:
                self._dle = True
                continue
            self._packet.append(b)
            if len(self._packet) >= 2 and len(self._packet) == 2 + struct.unpack_from("<H", self._packet)[0]:
                out.append(bytes(self._packet))
                self._packet = None
        return out
