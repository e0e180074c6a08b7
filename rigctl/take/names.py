"""Take names: explicit names are checked so they cannot escape the destination; interactive shoots get
scene / shot / take numbers that count up."""

from __future__ import annotations

import re
from pathlib import Path

from rigctl.errors import ParameterError

_SAFE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")
_AUTO = re.compile(r"^(?P<scene>[A-Za-z0-9]+)_(?P<shot>[A-Za-z0-9]+)_T(?P<take>\d{3,})$")


def check_take_name(name: str) -> str:
    """``name`` if it is a plain folder name; refuses paths, '..', hidden names and odd characters."""
    if name in (".", "..") or "/" in name or "\\" in name or ".." in name or "\x00" in name:
        raise ParameterError(f"take name {name!r} could escape the destination: use letters, digits, '.', '_', '-'")
    if not _SAFE.match(name):
        raise ParameterError(
            f"take name {name!r} is not allowed: start with a letter or digit, then letters, digits, '.', '_', '-' "
            "(at most 128 characters)"
        )
    return name


def next_take_name(destinations: list[Path], scene: str, shot: str) -> str:
    """``SCENE_SHOT_T001`` with the take number one above the highest on any destination."""
    check_take_name(f"{scene}_{shot}")
    highest = 0
    for dest in destinations:
        if not dest.is_dir():
            continue
        for entry in dest.iterdir():
            m = _AUTO.match(entry.name)
            if m and m.group("scene") == scene and m.group("shot") == shot:
                highest = max(highest, int(m.group("take")))
    return f"{scene}_{shot}_T{highest + 1:03d}"
