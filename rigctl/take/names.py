"""Take names: explicit names are checked so they cannot escape the destination; interactive shoots get
scene / shot / take numbers that count up."""

from __future__ import annotations

import re
from pathlib import Path

from rigctl.errors import ParameterError

_SAFE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")


def check_take_name(name: str) -> str:
    """``name`` if it is a plain folder name; refuses paths, '..', hidden names and odd characters."""
    if name in (".", "..") or "/" in name or "\\" in name or ".." in name or "\x00" in name:
        raise ParameterError(f"take name {name!r} could escape the destination: use letters, digits, '.', '_', '-'")
    if not _SAFE.fullmatch(name):  # not match with $: that lets a trailing newline through
        raise ParameterError(
            f"take name {name!r} is not allowed: start with a letter or digit, then letters, digits, '.', '_', '-' "
            "(at most 128 characters)"
        )
    return name


def take_name(scene: str, shot: str, number: int) -> str:
    """The shoot UI's take name: ``SCENE-SHOT-Tnn`` (two digits at least)."""
    return f"{scene}-{shot}-T{number:02d}"


def next_take_number(destinations: list[Path], scene: str, shot: str) -> int:
    """One above the highest take number of ``scene`` and ``shot`` on any destination (1 when there is none),
    so a restarted shoot goes on numbering instead of meeting the takes already on disk, recorded or not yet
    published."""
    check_take_name(take_name(scene, shot, 1))
    # a take still being recorded (or cut off) is under its hidden name (rigctl.take.staging): it counts too
    pattern = re.compile(rf"^\.?{re.escape(scene)}-{re.escape(shot)}-T(?P<take>\d{{2,}})(\.rigctl-recording)?$")
    highest = 0
    for dest in destinations:
        if not dest.is_dir():
            continue
        for entry in dest.iterdir():
            m = pattern.fullmatch(entry.name)
            if m:
                highest = max(highest, int(m.group("take")))
    return highest + 1


def next_take_name(destinations: list[Path], scene: str, shot: str) -> str:
    """``SCENE-SHOT-Tnn`` with the take number one above the highest on any destination."""
    return take_name(scene, shot, next_take_number(destinations, scene, shot))
