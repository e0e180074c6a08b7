"""Wire protocols: byte-exact against the published vectors (PROTOCOLS.md), round trips, and decoders
that never crash on garbage and find the next valid frame."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from rigctl.drivers.protocols import bmd_control as bc
from rigctl.drivers.protocols import bmd_tally, tsl31, tsl50
from rigctl.drivers.protocols import sdi_bridge as sb

from rigctl.errors import ProtocolError


def hx(text: str) -> bytes:
    return bytes.fromhex(text)


# ---- TSL UMD 3.1 ----------------------------------------------------------------------------------
def test_tsl31_vector() -> None:
    msg = tsl31.Tsl31Message(5, (True, False, False, False), 3, "CAM 5")
    frame = tsl31.encode(msg)
    assert frame == hx("85 31 43 41 4D 20 35 20 20 20 20 20 20 20 20 20 20 20")
    assert tsl31.decode(frame) == msg
    assert tsl31.encode(msg, pad_with_nul=True).endswith(b"5" + b"\0" * 11)


tsl31_messages = st.builds(
    tsl31.Tsl31Message,
    st.integers(0, 126),
    st.tuples(st.booleans(), st.booleans(), st.booleans(), st.booleans()),
    st.integers(0, 3),
    st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E), max_size=16),
)


@given(tsl31_messages)
def test_tsl31_round_trip(msg: tsl31.Tsl31Message) -> None:
    assert tsl31.decode(tsl31.encode(msg)) == msg


@given(st.binary(max_size=200), tsl31_messages)
def test_tsl31_stream_recovers_after_garbage(garbage: bytes, msg: tsl31.Tsl31Message) -> None:
    dec = tsl31.Tsl31Decoder()
    dec.feed(garbage)  # never raises
    got = dec.feed(tsl31.encode(msg) + tsl31.encode(msg))
    assert got[-1] == msg


def test_tsl31_stream_in_pieces_and_cut_frames() -> None:
    a = tsl31.encode(tsl31.Tsl31Message(1, (True, False, False, False), 3, "A"))
    b = tsl31.encode(tsl31.Tsl31Message(2, (False, True, False, False), 3, "B"))
    dec = tsl31.Tsl31Decoder()
    stream = a[:7] + b + a  # a cut frame, then two good ones
    got = [m for i in range(0, len(stream), 5) for m in dec.feed(stream[i : i + 5])]
    assert [m.text for m in got] == ["B", "A"] and dec.skipped == 7


@pytest.mark.parametrize(
    ("frame", "message"), [(b"\x85" * 18, "bit 7"), (b"\x05" + b" " * 17, "byte 0"), (b"\x85", "18 bytes")]
)
def test_tsl31_bad_frames(frame: bytes, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        tsl31.decode(frame)


# ---- TSL UMD 5.0 ----------------------------------------------------------------------------------
def test_tsl50_vector() -> None:
    pkt = tsl50.Tsl5Packet(0, (tsl50.Display(5, right=tsl50.RED, brightness=3, text="CAM5"),))
    data = tsl50.encode(pkt)
    assert data == hx("0E 00 00 00 00 00 05 00 C1 00 04 00 43 41 4D 35")
    assert tsl50.decode(data) == pkt


# The spec's layout written out field by field, 16-bit fields little-endian: PBC (0x16 = 22 bytes after it),
# VER 0, FLAGS 0 (ASCII), SCREEN 0; then per display INDEX, CONTROL (right tally bits 0-1, text tally 2-3,
# left tally 4-5, brightness 6-7), LENGTH, TEXT.
@pytest.mark.parametrize(
    ("index", "wire"),
    [
        (1000, "16 00 00 00 00 00 E8 03 C1 00 04 00 43 41 4D 35 07 00 9E 00 02 00 42 32"),
        (65534, "16 00 00 00 00 00 FE FF C1 00 04 00 43 41 4D 35 07 00 9E 00 02 00 42 32"),
        (tsl50.BROADCAST, "16 00 00 00 00 00 FF FF C1 00 04 00 43 41 4D 35 07 00 9E 00 02 00 42 32"),
    ],
)
def test_tsl50_high_indexes_byte_exact(index: int, wire: str) -> None:
    """A display index past TSL 3.1's 126 goes out as its two bytes, low first; the second display's CONTROL
    has a different value in every field: right green 2, text amber 3 << 2, left red 1 << 4, brightness
    2 << 6 = 0x9E. The codec encodes broadcast too; the rig file keeps cameras off it."""
    pkt = tsl50.Tsl5Packet(
        0,
        (
            tsl50.Display(index, right=tsl50.RED, brightness=3, text="CAM5"),
            tsl50.Display(7, right=tsl50.GREEN, text_tally=tsl50.AMBER, left=tsl50.RED, brightness=2, text="B2"),
        ),
    )
    data = tsl50.encode(pkt)
    assert data == hx(wire)
    assert tsl50.decode(data) == pkt


def test_tsl50_fields_past_16_bits_are_protocol_errors() -> None:
    with pytest.raises(ProtocolError, match=r"display index must be 0\.\.65535, got 65536"):
        tsl50.encode(tsl50.Tsl5Packet(0, (tsl50.Display(65536, text="X"),)))
    with pytest.raises(ProtocolError, match=r"screen must be 0\.\.65535, got 65536"):
        tsl50.encode(tsl50.Tsl5Packet(65536, ()))


displays = st.builds(
    tsl50.Display,
    st.integers(0, 0xFFFF),
    st.integers(0, 3),
    st.integers(0, 3),
    st.integers(0, 3),
    st.integers(0, 3),
    st.text(max_size=20),
)


@given(st.integers(0, 0xFFFF), st.lists(displays, max_size=5))
def test_tsl50_round_trip_utf16(screen: int, ds: list[tsl50.Display]) -> None:
    pkt = tsl50.Tsl5Packet(screen, tuple(ds), utf16=True)
    assert tsl50.decode(tsl50.encode(pkt)) == pkt


@given(st.binary(max_size=80))
def test_tsl50_garbage_only_protocol_errors(data: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        tsl50.decode(data)


def test_tsl50_tcp_framing_vectors() -> None:
    """Over TCP a packet goes after DLE STX (FE 02) with every FE inside it sent twice; PBC counts the packet
    before stuffing. The second packet is the index 65534 one above: its FE is doubled."""
    plain = hx("0E 00 00 00 00 00 05 00 C1 00 04 00 43 41 4D 35")
    assert tsl50.frame(plain) == hx("FE 02") + plain
    fe = hx("16 00 00 00 00 00 FE FF C1 00 04 00 43 41 4D 35 07 00 9E 00 02 00 42 32")
    assert tsl50.frame(fe) == hx("FE 02 16 00 00 00 00 00 FE FE FF C1 00 04 00 43 41 4D 35 07 00 9E 00 02 00 42 32")
    stream = tsl50.frame(plain) + tsl50.frame(fe)
    assert tsl50.Unframer().feed(stream) == [plain, fe]


@given(st.lists(st.lists(displays, max_size=4), min_size=1, max_size=4), st.data())
def test_tsl50_tcp_stream_in_any_pieces(packets: list[list[tsl50.Display]], data: st.DataObject) -> None:
    """Packets whose bytes hold FE anywhere (indexes, lengths, UTF-16 text), cut into arbitrary pieces: each
    comes out whole, in order, once; a piece that ends inside a DLE pair waits for the next."""
    wire = [tsl50.encode(tsl50.Tsl5Packet(0xFEFE, tuple(ds), utf16=True)) for ds in packets]
    stream = b"".join(tsl50.frame(w) for w in wire)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    unframer, got = tsl50.Unframer(), []
    for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        got += unframer.feed(stream[a:b])
    assert got == wire and [tsl50.decode(g) for g in got] == [tsl50.decode(w) for w in wire]


@pytest.mark.parametrize(
    ("stream", "message"),
    [
        ("0E 00", "byte 0: 0x0E between packets"),
        ("FE 03", "byte 1: DLE followed by 0x03, not STX"),
        ("FE 02 06 00 00 00 FE 00", "byte 7: DLE followed by 0x00 inside a packet"),
    ],
)
def test_tsl50_tcp_stream_errors_name_the_byte(stream: str, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        tsl50.Unframer().feed(hx(stream))


# ---- Blackmagic camera control --------------------------------------------------------------------
VECTORS = [
    (bc.Message(4, 0, 1), "04 04 00 00 00 01 00 00"),
    (bc.Message(255, 0, 6, bc.VOID, bc.ASSIGN, (1,)), "FF 05 00 00 00 06 00 00 01 00 00 00"),
    (bc.Message(4, 1, 5, bc.INT32, bc.ASSIGN, (10000,)), "04 08 00 00 01 05 03 00 10 27 00 00"),
    (bc.Message(4, 4, 2, bc.FIXED16, bc.OFFSET, (0.15,)), "04 06 00 00 04 02 80 01 33 01 00 00"),
    (bc.Message(255, 1, 0, bc.INT8, bc.ASSIGN, (24, 1, 3, 0, 0)), "FF 09 00 00 01 00 01 00 18 01 03 00 00 00 00 00"),
    (
        bc.Message(4, 8, 1, bc.FIXED16, bc.OFFSET, (0.0, -0.3, -0.3, 0.0)),
        "04 0C 00 00 08 01 80 01 00 00 9A FD 9A FD 00 00",
    ),
]


@pytest.mark.parametrize(("msg", "wire"), VECTORS)
def test_bmd_control_vectors(msg: bc.Message, wire: str) -> None:
    assert bc.encode_message(msg) == hx(wire)
    (back,) = bc.decode_packet(hx(wire))
    assert back.destination == msg.destination and back.category == msg.category
    assert back.parameter == msg.parameter and back.operation == msg.operation
    assert back.values == pytest.approx(msg.values, abs=1 / 2048)


def test_bmd_control_six_in_one_packet() -> None:
    packet = bc.encode_packet([m for m, _ in VECTORS])
    assert len(packet) == 76 and packet == b"".join(hx(w) for _, w in VECTORS)
    assert len(bc.decode_packet(packet)) == 6


def test_bmd_control_tally_and_reference_vectors() -> None:
    assert bc.encode_message(bc.Message(3, 5, 0, bc.FIXED16, bc.ASSIGN, (1.0,))) == hx(
        "03 06 00 00 05 00 80 00 00 08 00 00"
    )
    assert bc.encode_message(bc.Message(255, 6, 0, bc.INT8, bc.ASSIGN, (1,))) == hx(
        "FF 05 00 00 06 00 01 00 01 00 00 00"
    )


messages = st.one_of(
    st.builds(
        bc.Message,
        st.integers(0, 255),
        st.integers(0, 11),
        st.integers(0, 20),
        st.just(bc.INT32),
        st.integers(0, 1),
        st.lists(st.integers(-(2**31), 2**31 - 1), max_size=4).map(tuple),
    ),
    st.builds(
        bc.Message,
        st.integers(0, 255),
        st.integers(0, 11),
        st.integers(0, 20),
        st.just(bc.INT16),
        st.integers(0, 1),
        st.lists(st.integers(-(2**15), 2**15 - 1), max_size=8).map(tuple),
    ),
    st.builds(
        bc.Message,
        st.integers(0, 255),
        st.integers(0, 11),
        st.integers(0, 20),
        st.just(bc.FIXED16),
        st.integers(0, 1),
        st.lists(st.integers(-(2**15), 2**15 - 1).map(lambda v: v / 2048), max_size=8).map(tuple),
    ),
    st.builds(
        bc.Message,
        st.integers(0, 255),
        st.integers(0, 11),
        st.integers(0, 20),
        st.just(bc.UTF8),
        st.integers(0, 1),
        st.text(max_size=12).filter(lambda t: len(t.encode()) <= 40),
    ),
)


@given(st.lists(messages, max_size=3))
def test_bmd_control_round_trip(msgs: list[bc.Message]) -> None:
    assert bc.decode_packet(bc.encode_packet(msgs)) == msgs


@given(st.binary(max_size=80))
def test_bmd_control_garbage_only_protocol_errors(data: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        bc.decode_packet(data)


def test_bmd_control_limits() -> None:
    with pytest.raises(ProtocolError, match="exceeds 64"):
        bc.encode_message(bc.Message(1, 1, 5, bc.INT32, bc.ASSIGN, tuple(range(20))))
    with pytest.raises(ProtocolError, match="exceeds 255"):
        bc.encode_packet([bc.Message(1, 1, 5, bc.INT32, bc.ASSIGN, tuple(range(12)))] * 6)
    with pytest.raises(ProtocolError, match="byte 1: command length 60 runs past"):
        bc.decode_packet(hx("04 3C 00 00 01 05 03 00 10 27 00 00"))


# ---- Blackmagic embedded tally --------------------------------------------------------------------
def test_embedded_tally_vector() -> None:
    state = bmd_tally.EmbeddedTally(9, frozenset({3}), frozenset({4}))
    assert bmd_tally.encode(state) == hx("00 00 21 00 00 00")
    assert bmd_tally.decode(hx("00 00 21 00 00 00"), cameras=9) == state


@given(
    st.integers(1, 30).flatmap(
        lambda n: st.tuples(
            st.just(n), st.sets(st.integers(1, n)), st.sets(st.integers(1, n)), st.booleans(), st.booleans()
        )
    )
)
def test_embedded_tally_round_trip(args) -> None:  # type: ignore[no-untyped-def]
    n, program, preview, mp, mv = args
    state = bmd_tally.EmbeddedTally(n, frozenset(program), frozenset(preview), mp, mv)
    assert bmd_tally.decode(bmd_tally.encode(state), cameras=n) == state


@given(st.binary(max_size=40))
def test_embedded_tally_garbage_only_protocol_errors(data: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        bmd_tally.decode(data)


# ---- rigctl SDI bridge framing (docs/sdi-bridge-protocol.md) ---------------------------------------------
BRIDGE_VECTORS = [
    (sb.BridgeFrame(sb.HELLO, 0), "B5 62 01 01 00 00 44 C5"),
    (
        sb.BridgeFrame(sb.CONTROL, 7, hx("04 08 00 00 01 05 03 00 10 27 00 00")),
        "B5 62 01 02 07 0C 04 08 00 00 01 05 03 00 10 27 00 00 39 B6",
    ),
    (sb.BridgeFrame(sb.ACK, 7), "B5 62 01 80 07 00 B9 50"),
    (sb.BridgeFrame(sb.NAK, 8, bytes([1, 0])), "B5 62 01 81 08 02 01 00 A3 1B"),
    (sb.BridgeFrame(sb.QUERY, 9, sb.encode_query(4, 1, 5)), "B5 62 01 04 09 03 04 01 05 FA C3"),
    (sb.BridgeFrame(sb.HELLO_REPLY, 0, sb.encode_hello(sb.Hello(1, 3, "fw"))), "B5 62 01 82 00 04 01 03 66 77 E9 B4"),
]


def test_bridge_crc_check_value() -> None:
    assert sb.crc16(b"123456789") == 0x29B1  # CRC-16/CCITT-FALSE


@pytest.mark.parametrize(("frame", "wire"), BRIDGE_VECTORS)
def test_bridge_vectors(frame: sb.BridgeFrame, wire: str) -> None:
    assert sb.encode(frame) == hx(wire)
    assert sb.decode(hx(wire)) == frame


def test_bridge_documented_vectors_match_the_doc() -> None:
    doc = (Path(__file__).resolve().parents[2] / "docs" / "sdi-bridge-protocol.md").read_text()
    for _, wire in BRIDGE_VECTORS:
        assert f"`{wire}`" in doc


bridge_frames = st.builds(
    sb.BridgeFrame, st.sampled_from(sorted(sb.TYPES)), st.integers(0, 255), st.binary(max_size=sb.MAX_PAYLOAD)
)


@given(bridge_frames)
def test_bridge_round_trip(frame: sb.BridgeFrame) -> None:
    assert sb.decode(sb.encode(frame)) == frame


@given(st.binary(max_size=300), st.lists(bridge_frames, min_size=1, max_size=3), st.integers(1, 40))
def test_bridge_stream_recovers_after_garbage(garbage: bytes, frames: list[sb.BridgeFrame], chunk: int) -> None:
    dec = sb.FrameDecoder()
    got: list[sb.BridgeFrame] = []
    stream = garbage + b"".join(sb.encode(f) for f in frames)
    for i in range(0, len(stream), chunk):
        got += dec.feed(stream[i : i + chunk])
    # garbage can at worst swallow frames only by posing as a frame itself; the real frames all come out last
    assert got[-len(frames) :] == frames


@given(bridge_frames, st.integers(0, 10_000), st.integers(1, 255))
def test_bridge_corrupted_frame_is_dropped_and_next_is_found(frame: sb.BridgeFrame, where: int, flip: int) -> None:
    wire = bytearray(sb.encode(frame))
    wire[where % len(wire)] ^= flip
    dec = sb.FrameDecoder()
    following = sb.BridgeFrame(sb.ACK, 42)
    got = dec.feed(bytes(wire) + sb.encode(following))
    assert got[-1] == following
    assert frame not in got[:-1] or bytes(wire) == sb.encode(frame)


@given(st.binary(max_size=80))
def test_bridge_garbage_only_protocol_errors(data: bytes) -> None:
    with contextlib.suppress(ProtocolError):
        sb.decode(data)
    sb.FrameDecoder().feed(data)  # never raises


def test_bridge_refuses_bad_frames() -> None:
    good = sb.encode(sb.BridgeFrame(sb.HELLO, 1))
    with pytest.raises(ProtocolError, match="checksum"):
        sb.decode(good[:-1] + bytes([good[-1] ^ 1]))
    with pytest.raises(ProtocolError, match="sync"):
        sb.decode(b"\x00" + good[1:])
    with pytest.raises(ProtocolError, match="exceeds 255"):
        sb.encode(sb.BridgeFrame(sb.CONTROL, 0, bytes(256)))
    with pytest.raises(ProtocolError, match="type 0x55 unknown"):
        sb.encode(sb.BridgeFrame(0x55, 0))
