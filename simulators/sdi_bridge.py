"""A simulated SDI bridge on a pseudo-terminal: it speaks the bridge protocol (``docs/sdi-bridge-protocol.md``)
and applies the camera-control packets it is sent to the simulated cameras of a :class:`SimArray`, so that a
set exposure changes their images. Faults on purpose: unplug and replug, garbage on the line, slow replies,
no replies, a camera that ignores what it is told, a blind bridge that cannot read values back."""

from __future__ import annotations

import os
import time
from pathlib import Path

from rigctl.drivers.protocols import bmd_control, bmd_tally
from rigctl.drivers.protocols import sdi_bridge as proto
from rigctl.simulators.array import SimArray
from rigctl.simulators.pty_line import PtyDevice

from rigctl.errors import ProtocolError

REFERENCE = {0: "internal", 1: "program", 2: "external"}


class SimSdiBridge(PtyDevice):
    def __init__(
        self,
        array: SimArray | None,
        camera_ids: dict[str, int],
        link: Path | None = None,
        readback: bool = True,
        embedded_tally: bool = True,
    ) -> None:
        self.array = array
        self.by_id = {i: name for name, i in camera_ids.items()}
        self.readback = readback
        self.embedded_tally = embedded_tally
        # faults
        self.reply_delay_s = 0.0
        self.mute = False
        self.garbage_before_reply = b""
        self.ignoring: set[str] = set()  # cameras that do not apply what they are told
        # what the bridge saw
        self.packets: list[list[bmd_control.Message]] = []
        self.tally: bmd_tally.EmbeddedTally | None = None
        self.state: dict[str, dict[tuple[int, int], tuple[float, ...] | str]] = (
            array.control_state if array is not None else {name: {} for name in camera_ids}
        )
        self._last: tuple[int, int, bytes] | None = None  # (seq, type, reply) for repeated requests
        self._decoder = proto.FrameDecoder()
        super().__init__(link, "sim-bridge")
        self.plug()

    def plug(self) -> None:
        self._decoder = proto.FrameDecoder()
        super().plug()

    def on_data(self, fd: int, data: bytes) -> None:
        for frame in self._decoder.feed(data):
            reply = self._handle(frame)
            if reply is None or self.mute:
                continue
            if self.reply_delay_s:
                time.sleep(self.reply_delay_s)
            os.write(fd, self.garbage_before_reply + reply)

    # ---- the protocol -----------------------------------------------------------------------------------
    def _reply(self, ftype: int, seq: int, payload: bytes = b"") -> bytes:
        return proto.encode(proto.BridgeFrame(ftype, seq, payload))

    def _handle(self, frame: proto.BridgeFrame) -> bytes | None:
        if frame.type >= proto.ACK:
            return None  # replies are not for the bridge
        if frame.type == proto.HELLO:
            self._last = None  # a new session: sequence numbers start again
        elif self._last is not None and self._last[:2] == (frame.sequence, frame.type):
            return self._last[2]  # a retry of what was already applied: answer again, apply once
        reply = self._answer(frame)
        self._last = (frame.sequence, frame.type, reply)
        return reply

    def _answer(self, frame: proto.BridgeFrame) -> bytes:
        seq = frame.sequence
        if frame.type == proto.HELLO:
            caps = (proto.CAP_READBACK if self.readback else 0) | (
                proto.CAP_EMBEDDED_TALLY if self.embedded_tally else 0
            )
            return self._reply(
                proto.HELLO_REPLY, seq, proto.encode_hello(proto.Hello(1, caps, "rigctl sim bridge 1.0"))
            )
        if frame.type == proto.CONTROL:
            try:
                messages = bmd_control.decode_packet(frame.payload)
            except ProtocolError as exc:
                offset = int(str(exc).split(":")[0].removeprefix("byte ")) if str(exc).startswith("byte ") else 0
                return self._reply(proto.NAK, seq, proto.encode_nak(proto.NAK_PAYLOAD, offset))
            self.packets.append(messages)
            for msg in messages:
                self._apply(msg)
            return self._reply(proto.ACK, seq)
        if frame.type == proto.TALLY:
            if not self.embedded_tally:
                return self._reply(proto.NAK, seq, proto.encode_nak(proto.NAK_UNSUPPORTED))
            try:
                self.tally = bmd_tally.decode(frame.payload)
            except ProtocolError:
                return self._reply(proto.NAK, seq, proto.encode_nak(proto.NAK_PAYLOAD))
            return self._reply(proto.ACK, seq)
        if frame.type == proto.QUERY:
            if not self.readback:
                return self._reply(proto.NAK, seq, proto.encode_nak(proto.NAK_UNSUPPORTED))
            try:
                cam_id, category, parameter = proto.decode_query(frame.payload)
            except ProtocolError:
                return self._reply(proto.NAK, seq, proto.encode_nak(proto.NAK_PAYLOAD))
            name = self.by_id.get(cam_id)
            values = self.state.get(name, {}).get((category, parameter)) if name else None
            if values is None:
                return self._reply(proto.STATE, seq)  # the camera has not reported this value
            dtype = bmd_control.PARAMETERS.get((category, parameter), ("", bmd_control.INT32))[1]
            msg = bmd_control.Message(cam_id, category, parameter, dtype, bmd_control.ASSIGN, values)
            return self._reply(proto.STATE, seq, bmd_control.encode_message(msg))
        return self._reply(proto.NAK, seq, proto.encode_nak(proto.NAK_TYPE))

    def _apply(self, msg: bmd_control.Message) -> None:
        names = list(self.by_id.values()) if msg.destination == bmd_control.ALL_CAMERAS else []
        if msg.destination in self.by_id:
            names = [self.by_id[msg.destination]]
        for name in names:
            if name in self.ignoring:
                continue
            key = (msg.category, msg.parameter)
            values = msg.values
            old = self.state[name].get(key)
            if msg.operation == bmd_control.OFFSET and isinstance(values, tuple) and isinstance(old, tuple):
                values = tuple(a + b for a, b in zip(old, values, strict=False))
            self.state[name][key] = values
            if self.array is not None and isinstance(values, tuple) and values:
                self._effect(name, key, values[0])

    def _effect(self, name: str, key: tuple[int, int], value: float) -> None:
        """What the simulated camera does with a setting (the rest is stored and read back only)."""
        assert self.array is not None
        if key == (1, 5) and value > 0:
            self.array.exposure_us[name] = float(value)
        elif key == (1, 1) and value > 0:
            self.array.sensor_gain[name] = float(value)
        elif key == (6, 0) and int(value) in REFERENCE:
            self.array.reference_source[name] = REFERENCE[int(value)]
