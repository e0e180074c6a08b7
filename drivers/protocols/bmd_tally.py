"""Blackmagic embedded tally (Embedded Tally Control Protocol v1.0), carried in SDI ancillary data.

Byte 0: bit0 monitor program, bit1 monitor preview, bits 4-7 protocol version (0). Then 4 bits per
camera: camera 1 in bits 0-1 of byte 1 (bit0 program, bit1 preview), camera 2 in bits 4-5, camera 3 in
byte 2, and so on. Cameras are numbered from 1 as in the manual's text (its diagram numbers from 0:
to be checked on hardware).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rigctl.errors import ProtocolError


@dataclass(frozen=True)
class EmbeddedTally:
    cameras: int
    program: frozenset[int] = field(default_factory=frozenset)
    preview: frozenset[int] = field(default_factory=frozenset)
    monitor_program: bool = False
    monitor_preview: bool = False


def encode(state: EmbeddedTally) -> bytes:
    if not 1 <= state.cameras <= 254:
        raise ProtocolError(f"embedded tally covers 1..254 cameras, got {state.cameras}")
    out = bytearray(1 + (state.cameras + 1) // 2)
    out[0] = int(state.monitor_program) | (int(state.monitor_preview) << 1)
    for cam in state.program | state.preview:
        if not 1 <= cam <= state.cameras:
            raise ProtocolError(f"camera {cam} outside 1..{state.cameras}")
    for cam in range(1, state.cameras + 1):
        nibble = int(cam in state.program) | (int(cam in state.preview) << 1)
        out[1 + (cam - 1) // 2] |= nibble << (4 * ((cam - 1) % 2))
    return bytes(out)


def decode(data: bytes, cameras: int | None = None) -> EmbeddedTally:
    if not data:
        raise ProtocolError("embedded tally packet is empty")
    version = data[0] >> 4
    if version != 0:
        raise ProtocolError(f"byte 0: embedded tally version {version} unknown (this reads version 0)")
    n = cameras if cameras is not None else 2 * (len(data) - 1)
    if 1 + (n + 1) // 2 > len(data):
        raise ProtocolError(f"embedded tally of {len(data)} bytes cannot hold {n} cameras")
    program, preview = set(), set()
    for cam in range(1, n + 1):
        nibble = (data[1 + (cam - 1) // 2] >> (4 * ((cam - 1) % 2))) & 0xF
        if nibble & 1:
            program.add(cam)
        if nibble & 2:
            preview.add(cam)
    return EmbeddedTally(n, frozenset(program), frozenset(preview), bool(data[0] & 1), bool(data[0] & 2))
