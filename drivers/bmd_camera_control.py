"""Rig-wide camera settings as Blackmagic SDI camera-control messages, sent through an SDI bridge.

A setting is *confirmed* only when the bridge reads the camera's value back (bridges with the readback
capability) and it matches what was sent; a blind bridge leaves every setting *unconfirmed*.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

from rigctl.drivers.protocols import bmd_control as bmd
from rigctl.drivers.sdi_bridge import SdiBridge

from rigctl.camera_control import REFERENCE_SOURCES
from rigctl.errors import DeviceError
from rigctl.interfaces import SettingResult, SettingState

log = logging.getLogger(__name__)


def _to_av(f_number: float) -> float:
    return 2 * math.log2(f_number)  # aperture value: f = sqrt(2 ** AV)


def _from_av(av: float) -> float:
    return float(2 ** (av / 2))


# setting -> (category, parameter, data type, to protocol value, from protocol value)
MAPPING: dict[str, tuple[int, int, int, Callable[[float | str], float], Callable[[float], float | str]]] = {
    "exposure_us": (1, 5, bmd.INT32, lambda v: float(v), lambda p: int(p)),
    "gain": (1, 1, bmd.INT8, lambda v: float(v), lambda p: int(p)),
    "white_balance_k": (1, 2, bmd.INT16, lambda v: float(v), lambda p: int(p)),
    "focus": (0, 0, bmd.FIXED16, lambda v: float(v), lambda p: float(p)),
    "aperture_f": (0, 2, bmd.FIXED16, lambda v: _to_av(float(v)), _from_av),
    "reference": (
        6,
        0,
        bmd.INT8,
        lambda v: float(REFERENCE_SOURCES.index(str(v))),
        lambda p: REFERENCE_SOURCES[int(p)] if 0 <= int(p) < len(REFERENCE_SOURCES) else f"source {int(p)}",
    ),
}


def _as_sent(msg: bmd.Message) -> tuple[float, ...] | str:
    """The values as they travel (after the data type's quantisation)."""
    return bmd.decode_packet(bmd.encode_message(msg))[0].values


class BmdBridgeControl:
    """Camera settings through an :class:`SdiBridge`. ``camera_ids`` maps camera names to the camera
    numbers set in each camera's menu."""

    def __init__(self, bridge: SdiBridge, camera_ids: dict[str, int], confirm_timeout_s: float = 1.0) -> None:
        self.bridge = bridge
        self.camera_ids = camera_ids
        self.confirm_timeout_s = confirm_timeout_s
        self.can_confirm = bridge.hello.readback
        how = "reads values back" if self.can_confirm else "blind: cannot read values back"
        self.description = f"SDI bridge at {bridge.url} ({bridge.hello.firmware}; {how})"

    def _messages(self, values: dict[str, float | str], cameras: list[str]) -> list[tuple[str, str, bmd.Message]]:
        out = []
        for cam in cameras:
            for key, value in values.items():
                category, parameter, dtype, to_p, _ = MAPPING[key]
                msg = bmd.Message(self.camera_ids[cam], category, parameter, dtype, bmd.ASSIGN, (to_p(value),))
                out.append((cam, key, msg))
        return out

    def apply(self, values: dict[str, float | str], cameras: list[str]) -> list[SettingResult]:
        missing = [c for c in cameras if c not in self.camera_ids]
        if missing:
            raise DeviceError(f"camera_control.camera_ids has no camera number for {', '.join(missing)}")
        planned = self._messages(values, cameras)
        try:
            self.bridge.send_control([m for _, _, m in planned])
        except DeviceError as exc:
            log.warning("camera settings not sent: %s", exc)
            return [SettingResult(c, k, values[k], SettingState.FAILED, detail=str(exc)) for c, k, _ in planned]
        if not self.can_confirm:
            blind = SettingState.UNCONFIRMED
            return [SettingResult(c, k, values[k], blind, detail="sent; the bridge is blind") for c, k, _ in planned]
        results = []
        for cam, key, msg in planned:
            want = _as_sent(msg)
            reported: tuple[float, ...] | str | None = None
            deadline = time.monotonic() + self.confirm_timeout_s
            try:
                while True:
                    back = self.bridge.query(msg.destination, msg.category, msg.parameter)
                    reported = back.values if back is not None else None
                    if reported == want or time.monotonic() > deadline:
                        break
                    time.sleep(0.04)  # the camera reports a changed value a few frames later
            except DeviceError as exc:
                detail = f"readback failed: {exc}"
                results.append(SettingResult(cam, key, values[key], SettingState.UNCONFIRMED, detail=detail))
                continue
            from_p = MAPPING[key][4]
            shown = from_p(reported[0]) if isinstance(reported, tuple) and reported else None
            state = SettingState.CONFIRMED if reported == want else SettingState.MISMATCH
            results.append(SettingResult(cam, key, values[key], state, shown))
        return results

    def close(self) -> None:
        self.bridge.close()
