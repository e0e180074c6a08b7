"""Rig-wide camera settings: one set of values applied identically to every camera (or to one), and for each
camera and setting an honest state: *confirmed* when the camera's own report matches, *unconfirmed* when the
path can only say the command went out, *MISMATCH* when the camera reports something else, *FAILED* when the
command did not get through. Nothing is shown as applied on faith.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rigctl.errors import ParameterError, RigFileError
from rigctl.interfaces import SettingResult, SettingState
from rigctl.rig import Rig

REFERENCE_SOURCES = ("internal", "program", "external")


@dataclass(frozen=True)
class Setting:
    key: str
    label: str
    unit: str
    low: float
    high: float
    integer: bool = False
    choices: tuple[str, ...] = ()

    def check(self, value: float | str) -> float | str:
        if self.choices:
            if value not in self.choices:
                raise ParameterError(f"{self.key} must be one of {', '.join(self.choices)}, got {value!r}")
            return value
        if isinstance(value, str):
            raise ParameterError(f"{self.key} must be a number, got {value!r}")
        if not math.isfinite(value) or not self.low <= value <= self.high:
            raise ParameterError(f"{self.key} must be within {self.low:g}..{self.high:g} {self.unit}, got {value}")
        if self.integer and value != int(value):
            raise ParameterError(f"{self.key} must be a whole number of {self.unit}, got {value}")
        return int(value) if self.integer else float(value)


SETTINGS = {
    s.key: s
    for s in (
        Setting("exposure_us", "exposure", "us", 1, 1_000_000, integer=True),
        Setting("gain", "sensor gain", "x ISO 100", 1, 127, integer=True),
        Setting("white_balance_k", "white balance", "K", 2500, 10000, integer=True),
        Setting("focus", "focus", "of travel", 0.0, 1.0),
        Setting("aperture_f", "aperture", "f-number", 1.0, 22.0),
        Setting("reference", "reference source", "", 0, 0, choices=REFERENCE_SOURCES),
    )
}


def check_settings(values: dict[str, float | str]) -> dict[str, float | str]:
    """Validated values (unknown keys and values out of range are errors naming the setting)."""
    if not values:
        raise ParameterError("no camera setting given (see rigctl control --help)")
    out = {}
    for key, value in values.items():
        spec = SETTINGS.get(key)
        if spec is None:
            raise ParameterError(f"unknown camera setting {key!r} (known: {', '.join(SETTINGS)})")
        out[key] = spec.check(value)
    return out


def _show(value: float | str | None) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def format_results(results: list[SettingResult], locks: dict[str, str] | None = None) -> str:
    """A table: one row per camera, one column per setting, each cell the value and its state."""
    cameras = list(dict.fromkeys(r.camera for r in results))
    keys = list(dict.fromkeys(r.setting for r in results))
    by = {(r.camera, r.setting): r for r in results}
    header = ["camera", *keys] + (["reference lock"] if locks else [])
    rows = [header]
    for cam in cameras:
        row = [cam]
        for key in keys:
            r = by.get((cam, key))
            if r is None:
                row.append("")
                continue
            cell = f"{_show(r.requested)} {r.state}"
            if r.state is SettingState.MISMATCH:
                cell += f" (camera reports {_show(r.reported)})"
            elif r.state is SettingState.FAILED and r.detail:
                cell += f" ({r.detail})"
            row.append(cell)
        if locks:
            row.append(locks.get(cam, "not reported"))
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows)


def worst(results: list[SettingResult]) -> int:
    """Exit status: 0 when everything is confirmed or sent to a path that cannot confirm, 1 otherwise."""
    return 1 if any(r.state.is_problem for r in results) else 0


def camera_ids(rig: Rig) -> dict[str, int]:
    """Camera number per camera (as set in each camera's menu): ``camera_control.camera_ids``, default 1..N in
    row-major order, as the TSL addresses."""
    cc = rig.model.camera_control
    if cc is None:
        raise RigFileError(f"{rig.source}: rig {rig.name} has no camera_control section (add camera_control: bridge)")
    given = cc.camera_ids or {}
    return {name: given.get(name, i + 1) for i, name in enumerate(rig.camera_names)}
